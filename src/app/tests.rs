//! The application's own tests: every command against a small thermal plant (first order,
//! τ = 30 min, −43 °C per unit duty from 28 °C, 60 s dead time, as the carriers' identified
//! models have), through the same counts the board reads.

use super::*;
use crate::profile;
use crate::step::tests::counts_at;
use std::string::String;
use std::vec::Vec;

const LAWS: &[Law] = &[Law::Gpc, Law::Pi, Law::OnOff];

fn config() -> AppConfig {
    AppConfig {
        carrier: ValidConfig::DEFAULT,
        adaptive: profile::ADAPTIVE_GPC,
        laws: LAWS,
        setpoint_c: 4.0,
        firmware: "hter test",
        history_save_samples: 360,
        model_save_samples: 1440,
    }
}

fn boot() -> Boot {
    Boot::NEW
}

/// The app in front of a first-order plant holding 4 °C.
struct Bench {
    app: App,
    t_ms: u64,
    load_c: f32,
    /// Duties applied in the last 60 s, oldest first: the plant's dead time.
    pipe: std::collections::VecDeque<f32>,
    saves: Vec<Save>,
    /// A count of noise on every other sample (a load at rest otherwise gives the same counts
    /// sample after sample, which the stuck-converter check takes for a frozen front end).
    dither: bool,
    /// The RTD lead's own error, °C: the sensor reads the load this much warm (a lead or
    /// connector fault, which the offset watch measures and subtracts).
    lead_c: f32,
    /// The load held at this temperature whatever the duty (a cabinet that cannot cool).
    pinned_c: Option<f32>,
    /// What the board's module-side sense reads each sample (`None`: the reference board).
    #[cfg(feature = "module-sense")]
    module_v: Option<f32>,
}

impl Bench {
    fn new(boot: &Boot) -> Bench {
        let hold = 24.0 / 43.0;
        Bench {
            app: App::new(config(), boot),
            t_ms: 0,
            load_c: 4.0,
            pipe: [hold; 6].into(),
            saves: Vec::new(),
            dither: false,
            lead_c: 0.0,
            pinned_c: None,
            #[cfg(feature = "module-sense")]
            module_v: None,
        }
    }

    fn run(&mut self, samples: usize) -> SampleOut {
        let mut last = None;
        for _ in 0..samples {
            let out = self.app.sample(&SampleIn {
                t_ms: self.t_ms,
                counts: counts_at(self.load_c + self.lead_c)
                    + u32::from(self.dither && !self.t_ms.is_multiple_of(20_000)),
                reference_ok: true,
                board: crate::step::BoardReadings {
                    #[cfg(feature = "module-sense")]
                    module_v: self.module_v,
                    ..Default::default()
                },
            });
            // 10 s of a τ = 1800 s plant: equilibrium 28 − 43·duty, the duty of 60 s ago.
            self.pipe.push_back(out.step.duty.get());
            let duty = self.pipe.pop_front().unwrap();
            let eq = 28.0 - 43.0 * duty;
            self.load_c += (eq - self.load_c) * (10.0 / 1800.0);
            if let Some(c) = self.pinned_c {
                self.load_c = c;
            }
            self.t_ms += 10_000;
            self.drain();
            last = Some(out);
        }
        last.unwrap()
    }

    fn drain(&mut self) {
        while let Some(s) = self.app.next_save() {
            self.saves.push(s);
        }
    }

    fn send(&mut self, line: &str) -> String {
        let mut out = String::new();
        assert_eq!(self.app.handle(line, &mut out), Handled::Done, "{line}");
        self.drain();
        out
    }

    fn status(&mut self) -> Vec<(String, String)> {
        let reply = self.send("status");
        let mut lines: Vec<&str> = reply.split("\r\n").collect();
        assert_eq!(lines.pop(), Some(""));
        assert_eq!(lines.pop(), Some("ok"));
        lines.iter().map(|l| l.split_once('=').map(|(k, v)| (k.into(), v.into())).expect(l)).collect()
    }

    fn field(&mut self, key: &str) -> String {
        self.status().into_iter().find(|(k, _)| k == key).unwrap_or_else(|| panic!("{key}")).1
    }

    fn settings_saves(&self) -> usize {
        self.saves.iter().filter(|s| matches!(s, Save::Settings(_))).count()
    }

    fn setting_logs(&self) -> Vec<SettingKey> {
        self.saves
            .iter()
            .filter_map(|s| match s {
                Save::Log(LogEntry::Setting { key, .. }) => Some(*key),
                _ => None,
            })
            .collect()
    }
}

#[test]
fn status_has_every_field_of_the_contract_in_order() {
    let mut b = Bench::new(&boot());
    b.run(30);
    let keys: Vec<String> = b.status().into_iter().map(|(k, _)| k).collect();
    let want = [
        "t_s",
        "temp_c",
        "sensor_offset_c",
        "setpoint_c",
        "duty",
        "mode",
        "alarm",
        "controller",
        "adaptive",
        "controllers",
        "model_a",
        "model_b",
        "model_k",
        "cabinet_a",
        "cabinet_b",
        "cabinet_k",
        "holdover_s",
        "resets",
        "firmware",
        "commissioning",
        "settings_version",
        "flash",
    ];
    assert_eq!(keys, want);
    assert_eq!(b.field("controller"), "gpc");
    assert_eq!(b.field("controllers"), "gpc,pi,onoff");
    assert_eq!(b.field("mode"), "normal");
    assert_eq!(b.field("resets"), "0", "a new board's first boot begins the record: no reset");
    assert_eq!(b.field("t_s"), "290.0");
    assert_eq!(b.field("model_k"), profile::START_MODEL_HTER1.k().to_string());
    // Never commissioned: no cabinet model; the holdover runs on the build's start model.
    assert_eq!(b.field("cabinet_k"), "-");
    assert_eq!(b.app.carrier().holdover_model(), Some(profile::START_MODEL_HTER1));
}

/// A bench booted with the PI, which holds this crude plant steadily.
fn bench_under_pi() -> Bench {
    Bench::new(&Boot {
        settings: Some(SettingsRecord { law: Law::Pi, ..App::new(config(), &boot()).settings }),
        ..boot()
    })
}

#[test]
#[cfg(feature = "holdover")]
fn status_shows_no_holdover_until_the_mean_duty_has_settled_after_boot() {
    // Holding 4 °C from the first sample: the mean duty started at 0 showed 172800 (48 h, the
    // horizon) for the first ≈ 10 minutes, then thousands of seconds. Now `-` until the mean has
    // settled, then the estimate, minutes.
    let mut b = bench_under_pi();
    for n in 1..=crate::holdover::SETTLE_SAMPLES {
        b.run(1);
        assert_eq!(b.field("holdover_s"), "-", "sample {n}");
    }
    let shown = (0..30)
        .find_map(|_| {
            b.run(1);
            b.field("holdover_s").parse::<f32>().ok()
        })
        .expect("an estimate one sweep after the mean settled");
    assert!((60.0..3600.0).contains(&shown), "{shown}");
}

#[test]
#[cfg(feature = "holdover")]
fn status_shows_the_holdover_estimate_as_a_number_that_follows_the_stored_model() {
    // Under the PI, which holds this crude plant steadily (the estimate runs on the stored
    // model whatever law drives).
    let mut b = bench_under_pi();
    // Holding 4 °C for 25 min: the mean duty has settled, sweeps have finished (and this
    // noiseless bench's readings do not yet repeat long enough to look stuck: a sensor fault,
    // no estimate then nor for 15 minutes after).
    let out = b.run(150);
    let step = out.step.holdover_s.expect("the step has an estimate");
    let shown: f32 = b.field("holdover_s").parse().expect("holdover_s is a number");
    assert_eq!(shown, (step + 0.5).floor(), "status shows the step's estimate in whole seconds");
    // Minutes, not zero nor the 48 h horizon: the stored model passes 8 °C from 4 °C at the
    // holding duty.
    assert!((60.0..3600.0).contains(&shown), "{shown}");
    // A model that warms more slowly in its first minutes (H-TER II's start model: fast lag
    // τ ≈ 105 s against ≈ 36 s, one more sample of delay) is the holdover's model from its first
    // sweep: the estimate grows (measured 470 → 576 s).
    assert_eq!(b.send("set model -1.904667,0.904945;-0.012378,-0.0001;6"), "ok\r\n");
    let slower = (0..400)
        .filter_map(|_| {
            b.run(1);
            b.field("holdover_s").parse::<f32>().ok()
        })
        .last()
        .expect("holdover_s is a number");
    assert!(slower > 1.1 * shown, "{slower} s on H-TER II's model vs {shown} s");
}

#[test]
fn an_accepted_setpoint_is_used_stored_and_logged_and_the_load_follows() {
    // Under the PI: the self-tuners follow on the physical plant (tests/virtual_board.rs); this
    // plant is too crude for their start model.
    let mut b = bench_under_pi();
    b.run(60);
    assert_eq!(b.send("set setpoint_c 5"), "ok\r\n");
    assert_eq!(b.settings_saves(), 1);
    assert_eq!(b.setting_logs(), [SettingKey::Setpoint]);
    assert_eq!(b.app.settings().setpoint_c, 5.0);
    assert_eq!(b.app.settings().seq, 1);
    let out = b.run(1080);
    assert_eq!(out.step.setpoint_c.0, 5.0);
    assert!((b.load_c - 5.0).abs() < 0.3, "the load followed: {}", b.load_c);
    assert_eq!(b.field("settings_version"), "1");
}

#[test]
fn a_refused_value_changes_nothing_stores_nothing_and_says_why_in_one_line() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let before = *b.app.settings();
    let saves = b.saves.len();
    for (line, reply) in [
        ("set setpoint_c 12", "err setpoint_c: 12 is outside 2.5…7.5\r\n"),
        ("set setpoint_c nan", "err setpoint_c: not a decimal number\r\n"),
        ("set setpoint_c -inf", "err setpoint_c: not a decimal number\r\n"),
        ("set controller igmvc", "err controller: not a law this build links (see status: controllers)\r\n"),
        ("set cal_ice 3.0,0.0", "err cal_ice: the points give a gain outside 0.9…1.1\r\n"),
        ("set cal_warm 0.5,0.5", "err cal_warm: the two points are less than 1 °C apart\r\n"),
        ("set model 1.2,0.1;-0.02,-0.01;5", "err model: A is not stable (a root on or outside the unit circle)\r\n"),
        (
            "set model -1.8,0.81;0.02,-0.01;5",
            "err model: not a monotone cooling (A two real lags, b0 <= 0, the slow lag cooling: b0*p1 + b1 <= 0)\r\n",
        ),
        (
            "set model -1.8,0.95;-0.02,-0.01;5",
            "err model: not a monotone cooling (A two real lags, b0 <= 0, the slow lag cooling: b0*p1 + b1 <= 0)\r\n",
        ),
        (
            "set model -1.94,0.9401;-0.02,0.0201;9",
            "err model: not a monotone cooling (A two real lags, b0 <= 0, the slow lag cooling: b0*p1 + b1 <= 0)\r\n",
        ),
        ("set model -1.8,0.81;-0.00001,0;5", "err model: static gain outside the self-tuner's plausible range\r\n"),
        ("identify now", "err line: usage: too many words\r\n"),
    ] {
        assert_eq!(b.send(line), reply, "{line}");
    }
    assert_eq!(*b.app.settings(), before);
    assert_eq!(b.saves.len(), saves, "nothing stored or logged");
    assert_eq!(b.run(1).step.setpoint_c.0, 4.0);
}

#[test]
fn switching_the_law_is_bumpless_and_every_law_of_the_build_runs() {
    let mut b = Bench::new(&boot());
    b.run(360);
    // On-off first: self-tuning GPC swings between the rails on this bench (its plant's dead
    // time is a sample longer than the start model's) with the load up to 1 °C above the
    // setpoint, and a PI taking over from a rail starts at its proportional term on that error
    // (its integral, clamped to 0…1, cannot hold the negative remainder). From on-off the error
    // is within its ±0.3 °C band.
    for law in ["onoff", "pi", "gpc"] {
        let before = b.run(1).step.duty.get();
        let reply = b.send(&format!("set controller {law}"));
        // On-Off's acceptance carries its warning (switching_to_on_off_is_accepted_with_a_warning_line).
        let warned = law == "onoff" && reply.starts_with("warning: ") && reply.ends_with("\r\nok\r\n");
        assert!(reply == "ok\r\n" || warned, "{law}: {reply}");
        assert_eq!(b.field("controller"), law);
        if law != "onoff" {
            // The new law starts from the applied duty.
            let after = b.run(1).step.duty.get();
            assert!((after - before).abs() < 0.15, "{law}: {before} → {after}");
        }
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for _ in 0..720 {
            b.run(1);
            lo = lo.min(b.load_c);
            hi = hi.max(b.load_c);
        }
        assert!(lo >= 2.0 && hi <= 8.0, "{law} keeps 2…8 °C: {lo}…{hi}");
    }
    assert_eq!(b.setting_logs(), [SettingKey::Controller; 3]);
}

#[test]
fn calibration_points_shift_the_reading_from_the_next_sample() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let load = b.load_c;
    let raw = b.run(1).step.raw_c.unwrap().0;
    assert!((raw - load).abs() < 0.02, "{raw} at {load}");
    // The channel reads 0.5 °C high at the ice point and at 25 °C: offset −0.5.
    assert_eq!(b.send("set cal_ice 0.5,0.0"), "ok\r\n");
    assert_eq!(b.send("set cal_warm 25.5,25.0"), "ok\r\n");
    let load = b.load_c;
    let cal = b.run(1).step.raw_c.unwrap().0;
    assert!((load - cal - 0.5).abs() < 0.02, "{cal} at {load}");
    let get = b.send("get");
    assert!(get.contains("cal_ice=0.50,0.00\r\n") && get.contains("cal_warm=25.50,25.00\r\n"), "{get}");
}

/// The line the app's settings give.
fn line(b: &Bench) -> TwoPoint {
    b.app.settings().calibration().unwrap()
}

/// Runs `samples` samples; every sample's reading against the load through the app's
/// calibration: the worst difference of the offset-corrected reading, that of the filtered one
/// (which lags a moving load by about a sample: ≤ 0.1 °C here, the load moving at most
/// 0.1 °C a sample), °C, the events, and each sample's indication.
fn against_truth(b: &mut Bench, samples: usize) -> (f32, f32, Vec<EventKind>, Vec<Indication>) {
    let (mut raw, mut filtered, mut events, mut alarms) = (0.0f32, 0.0f32, Vec::new(), Vec::new());
    for _ in 0..samples {
        // The reading of this sample is of the load before the plant's step.
        let truth = line(b).apply(crate::units::Celsius(b.load_c)).0;
        let out = b.run(1);
        events.extend(out.step.events.iter().map(|e| e.kind));
        let Some(r) = out.step.raw_c else { panic!("no reading: {events:?}") };
        raw = raw.max((r.0 - truth).abs());
        filtered = filtered.max((out.step.temp_c.0 - truth).abs());
        alarms.push(out.alarm);
    }
    (raw, filtered, events, alarms)
}

/// [`against_truth`] with no alarm on any sample: the raw and filtered errors and the events.
fn run_against_truth(b: &mut Bench, samples: usize) -> (f32, f32, Vec<EventKind>) {
    let (raw, filtered, events, alarms) = against_truth(b, samples);
    assert!(alarms.iter().all(|a| *a == Indication::Off), "{alarms:?} {events:?}");
    (raw, filtered, events)
}

/// A bench whose counts alternate by one (the stuck check never sees a repeat), switched to the
/// PI and run for an hour (360 samples) holding 4 °C.
fn holding_with_dither() -> Bench {
    let mut b = Bench::new(&boot());
    b.dither = true;
    assert_eq!(b.send("set controller pi"), "ok\r\n");
    b.run(360);
    b
}

#[test]
fn a_calibration_change_moves_the_reading_by_its_change_and_is_no_sensor_offset() {
    // `hter virtual-board` at 4 °C: `set cal_ice 0.0,1.4` was accepted, then the offset watch
    // took the reading's step for a sensor offset, subtracted it (temp_c stayed 4.00) and
    // raised `sensor_offset` with an alarm.
    let mut b = holding_with_dither();
    let before = b.run(1).step.temp_c.0;
    let old = line(&b);
    assert_eq!(b.send("set cal_ice 0.0,1.4"), "ok\r\n");
    let change = line(&b).apply(crate::units::Celsius(b.load_c)).0 - old.apply(crate::units::Celsius(b.load_c)).0;
    assert!(change > 1.0, "{change}");
    // At once: the next sample's reading is the load through the new line.
    let first = b.run(1).step.temp_c.0;
    assert!((first - before - change).abs() < 0.03, "{before} → {first}, the line moved it {change}");
    // And from then on, with the controller bringing the new reading to 4 °C.
    let (raw, filtered, events) = run_against_truth(&mut b, 180);
    assert!(raw < 0.03 && filtered < 0.15, "{raw} {filtered}");
    assert!(!events.contains(&EventKind::SensorOffset), "{events:?}");
    assert!(b.app.carrier().config().cal == line(&b));
}

#[test]
fn alternating_calibration_changes_cannot_add_up_an_offset() {
    // The bug hunt's pairs (`set cal_ice 0.0,1.4`, `set cal_ice 0,0`, 36 and 48 samples apart
    // at --speed 600) left the board reading 4.00 °C for ≈ 9 h with the load at ≈ 9 °C; here
    // every spacing from one sample to the offset watch's confirmation and beyond.
    let mut b = holding_with_dither();
    let mut all = Vec::new();
    for k in 0..40 {
        let (ice, wait) = if k % 2 == 0 { ("0.0,1.4", 1 + k % 7) } else { ("0,0", 1 + (k / 2) % 5) };
        assert_eq!(b.send(&format!("set cal_ice {ice}")), "ok\r\n");
        let (raw, filtered, events) = run_against_truth(&mut b, wait);
        assert!(raw < 0.03 && filtered < 0.15, "change {k} ({ice}, {wait} samples): {raw} {filtered}");
        all.extend(events);
    }
    let (raw, filtered, events) = run_against_truth(&mut b, 360);
    assert!(raw < 0.03 && filtered < 0.15, "{raw} {filtered}");
    all.extend(events);
    assert!(!all.contains(&EventKind::SensorOffset), "{all:?}");
    // The load is where the reading says, through the last line (`set cal_ice 0,0`: none).
    let shown = b.run(1).step.temp_c.0;
    assert!((shown - 4.0).abs() < 0.1 && (b.load_c - 4.0).abs() < 0.1, "shown {shown}, load {}", b.load_c);
}

#[test]
fn a_plausible_model_restarts_the_self_tuner_from_it_and_is_stored() {
    let mut b = Bench::new(&boot());
    b.run(10);
    assert_eq!(b.send("set model -1.859405,0.859802;-0.014713,-0.003021;8"), "ok\r\n");
    assert_eq!(b.field("model_k"), "8");
    assert_eq!(b.field("model_a"), "-1.859405,0.859802");
    assert!(b.saves.iter().any(|s| matches!(s, Save::Model(r) if r.k == 8)));
    assert_eq!(b.setting_logs(), [SettingKey::Model]);
    // It is the cabinet model too: the holdover's, in its own record.
    assert_eq!(b.field("cabinet_a"), "-1.859405,0.859802");
    assert_eq!(b.field("cabinet_k"), "8");
    #[cfg(feature = "holdover")]
    assert!(b.saves.iter().any(|s| matches!(s, Save::Cabinet(r) if r.k == 8)));
}

/// H-TER I's output-error model (two cooling lags in parallel, b1 > 0): the cabinet model, not
/// the self-tuner's.
const PARALLEL_LAGS: &str = "-1.938996,0.939181;-0.279814,0.271719;9";

#[test]
fn a_monotone_model_with_b1_above_0_becomes_the_cabinet_model_only() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let before = (b.field("model_a"), b.field("model_k"));
    assert_eq!(b.send(&format!("set model {PARALLEL_LAGS}")), "ok\r\n");
    assert_eq!((b.field("model_a"), b.field("model_k")), before, "the self-tuner keeps its model");
    assert_eq!(b.field("cabinet_a"), "-1.938996,0.939181");
    assert_eq!(b.field("cabinet_b"), "-0.279814,0.271719");
    assert_eq!(b.field("cabinet_k"), "9");
    let cab = b.app.cabinet().unwrap();
    assert_eq!(b.app.carrier().holdover_model(), Some(cab));
    assert!(!b.saves.iter().any(|s| matches!(s, Save::Model(_))), "the model record is the self-tuner's");
    assert_eq!(b.setting_logs(), [SettingKey::Model]);
    #[cfg(feature = "holdover")]
    {
        let Some(Save::Cabinet(rec)) = b.saves.iter().rev().find(|s| matches!(s, Save::Cabinet(_))).copied() else {
            panic!("the cabinet record is stored")
        };
        // Restored at the next boot exactly as accepted, and the holdover runs on it there.
        let back = crate::persist::CabinetRecord::decode(&rec.encode(), &profile::ADAPTIVE_GPC).unwrap();
        assert_eq!(back, cab);
        let mut again = Bench::new(&Boot { cabinet: Some(back), ..boot() });
        assert_eq!(again.app.carrier().holdover_model(), Some(cab));
        assert_eq!(again.field("cabinet_k"), "9");
    }
}

#[test]
#[cfg(feature = "holdover")]
fn a_restored_self_tuner_model_does_not_replace_the_cabinet_model_in_the_holdover() {
    // The self-tuner's periodically saved estimate comes back as its start; the holdover stays
    // on the cabinet model (or the build's start model without one).
    let Ok(Some(Command::Set(SetRequest::Model(cab)))) = Command::parse(&format!("set model {PARALLEL_LAGS}")) else {
        panic!()
    };
    let estimate = Model::second_order([-1.859405, 0.859802], [-0.014713, -0.003021], 8).unwrap();
    let restored = profile::ADAPTIVE_GPC.resumed_from(estimate);
    let mut b = Bench::new(&Boot { adaptive: Some(restored), cabinet: Some(cab), ..boot() });
    assert_eq!(b.app.carrier().holdover_model(), Some(cab));
    assert_eq!(b.field("model_k"), "8");
    let b = Bench::new(&Boot { adaptive: Some(restored), ..boot() });
    assert_eq!(b.app.carrier().holdover_model(), Some(profile::START_MODEL_HTER1));
    // A stored cabinet record the upload check would refuse is refused as a record.
    let heating = crate::persist::CabinetRecord { theta: [-1.94, 0.9401, -0.02, 0.0201], k: 9 };
    let bytes = heating.encode();
    assert_eq!(
        crate::persist::CabinetRecord::decode(&bytes, &profile::ADAPTIVE_GPC),
        Err(crate::persist::DecodeError::Implausible)
    );
    let mut bytes = crate::persist::CabinetRecord::from_model(&cab).unwrap().encode();
    bytes[4] ^= 1;
    assert_eq!(
        crate::persist::CabinetRecord::decode(&bytes, &profile::ADAPTIVE_GPC),
        Err(crate::persist::DecodeError::Crc)
    );
}

#[test]
fn stored_settings_come_back_at_the_next_boot_and_bad_ones_do_not() {
    let mut b = Bench::new(&boot());
    b.run(10);
    b.send("set setpoint_c 6.5");
    b.send("set controller pi");
    let Some(Save::Settings(rec)) = b.saves.iter().rev().find(|s| matches!(s, Save::Settings(_))).copied() else {
        panic!()
    };
    let back = SettingsRecord::decode(&rec.encode()).unwrap();
    let mut again = Bench::new(&Boot { settings: Some(back), ..boot() });
    assert_eq!(again.run(1).step.setpoint_c.0, 6.5);
    assert_eq!(again.field("controller"), "pi");
    assert_eq!(again.field("settings_version"), "2");
    // A record whose value the interface would refuse is refused as a record.
    let mut bytes = SettingsRecord { setpoint_c: 12.0, ..rec }.encode();
    assert_eq!(SettingsRecord::decode(&bytes), Err(crate::persist::DecodeError::OutOfRange));
    bytes[6] ^= 1;
    assert_eq!(SettingsRecord::decode(&bytes), Err(crate::persist::DecodeError::Crc));
}

/// A settings record stored by a build that links another law (the `igmvc` interface build's,
/// restored by the default one): the law this build does not link falls back to its default,
/// and the rest of the record, the setpoint and the ice-bath calibration, still applies. It
/// used to be dropped whole, and the board then read through the identity calibration (not even
/// the calibration the boot found), 0.5 °C off here.
#[test]
fn stored_settings_with_a_law_this_build_does_not_link_keep_their_setpoint_and_calibration() {
    let stored =
        SettingsRecord { seq: 7, setpoint_c: 6.5, law: Law::Igmvc, cal_ice: [0.5, 0.0], cal_warm: [25.5, 25.0] };
    assert!(!LAWS.contains(&stored.law));
    let back = SettingsRecord::decode(&stored.encode()).expect("a valid record");
    let mut b = Bench::new(&Boot { settings: Some(back), ..boot() });
    b.run(10);
    assert_eq!(b.field("controller"), "gpc", "the build's default law");
    assert_eq!(b.app.settings().setpoint_c, 6.5);
    assert_eq!(b.app.settings().calibration(), stored.calibration());
    let load = b.load_c;
    let cal = b.run(1).step.raw_c.unwrap().0;
    assert!((load - cal - 0.5).abs() < 0.02, "the stored calibration applies: {cal} at {load}");
}

/// A boot that repaired more torn pages than the outbox holds events still hands over its
/// history (this boot's reset, the previous boot's fault, the pages lost): the events filled
/// the outbox first and the history, pushed last, was dropped, so none of it reached flash
/// before the next hourly store.
#[test]
fn a_boot_with_many_repaired_pages_still_stores_its_history() {
    let fault = crate::failsafe::StopInfo::new(crate::failsafe::StopKind::HardFault, 0x0800_1234, 0, 0);
    let mut b = Bench::new(&Boot {
        pages_lost: 20,
        stops: Stops { earlier: None, latest: Some(fault), fresh: true },
        ..boot()
    });
    b.drain();
    let h = b.saves.iter().find_map(|s| match s {
        Save::History(h) | Save::AlarmHistory(h) => Some(*h),
        _ => None,
    });
    let h = h.expect("the boot's history is handed over");
    assert_eq!(h.flash_pages_lost, 20);
    assert_eq!(h.stops_of(crate::failsafe::StopKind::HardFault), 1);
    assert_eq!(h.resets_by(ResetCause::Other), 1);
}

/// A board that stops within the write gate's hold-off of every boot (here a panic 20 s in,
/// the same one each time: a fault loop) still gets the stop into the cold-chain record: the
/// first boot that finds a stop the stored history lacks stores its history at once on a good
/// supply; the same stop again waits for the hold-off, so the loop does not write at every boot;
/// another stop goes at once again. Behind the hold-off, nothing of the loop reached flash.
#[test]
fn a_new_fail_safe_stop_reaches_the_record_before_the_next_stop() {
    use crate::failsafe::{panic_info, StopInfo, StopKind};
    use crate::persist::{LastStop, PendingSaves, WriteGate};
    let panic = panic_info("src/step.rs", 417);
    let hard_fault = StopInfo::new(StopKind::HardFault, 0x0800_1234, 0, 0x8200);
    let mut stored = HistoryRecord::EMPTY;
    let mut writes = Vec::new();
    for (n, fault) in [panic; 10].into_iter().chain([hard_fault]).enumerate() {
        let mut app = App::new(
            config(),
            &Boot { history: stored, stops: Stops { earlier: None, latest: Some(fault), fresh: true }, ..boot() },
        );
        let (mut gate, mut pending) = (WriteGate::firmware(), PendingSaves::EMPTY);
        while let Some(s) = app.next_save() {
            pending.put(s);
        }
        // A sample every Ts on a good supply, the first at boot (the PVD's reading), until the
        // stop 20 s in.
        for t in (0..20_000).step_by(10_000) {
            gate.note_supply(t, true);
            while let Some(s) = pending.next(&gate, t) {
                if let Save::History(h) | Save::AlarmHistory(h) = s {
                    stored = h;
                    writes.push(n);
                }
            }
        }
    }
    assert_eq!(writes, [0, 10], "the loop's first boot and the new stop's");
    assert_eq!(stored.last_stop, Some(LastStop::from(&hard_fault)));
    assert_eq!((stored.stops_of(StopKind::Panic), stored.stops_of(StopKind::HardFault)), (1, 1));
    // No stop: behind the hold-off as before (a power bounce writes nothing).
    let quiet = Boot { history: stored, ..boot() };
    assert!(matches!(quiet.history_save(stored), Save::History(_)));
}

/// The same fault loop on the log: the new stop's `board_fault` row, which the boot's first
/// sample logs, reaches flash before the stop 20 s in, as its history does; the repeats wait as
/// their history does. Behind the write gate's hold-off, `history` and `hter report` showed no
/// board fault at all for a board that stopped within the minute of every boot.
#[test]
fn a_new_fail_safe_stops_row_reaches_the_log_before_the_next_stop() {
    use crate::failsafe::{panic_info, StopInfo, StopKind};
    use crate::persist::{PendingSaves, WriteGate};
    let panic = panic_info("src/step.rs", 417);
    let hard_fault = StopInfo::new(StopKind::HardFault, 0x0800_1234, 0, 0x8200);
    let mut stored = HistoryRecord::EMPTY;
    let mut rows = Vec::new();
    for (n, fault) in [panic; 4].into_iter().chain([hard_fault]).enumerate() {
        let mut b = Bench::new(&Boot {
            history: stored,
            stops: Stops { earlier: None, latest: Some(fault), fresh: true },
            ..boot()
        });
        b.drain();
        let (mut gate, mut pending) = (WriteGate::firmware(), PendingSaves::EMPTY);
        // The boot's supply reading, then a sample every Ts until the stop 20 s in.
        gate.note_supply(0, true);
        for t in [0, 10_000] {
            if t > 0 {
                b.run(1);
            }
            gate.note_supply(t, true);
            for s in b.saves.drain(..) {
                pending.put(s);
            }
            while let Some(s) = pending.next(&gate, t) {
                match s {
                    Save::History(h) | Save::AlarmHistory(h) => stored = h,
                    Save::Log(LogEntry::Event { kind: EventKind::BoardFault(k), .. }) => rows.push((n, k)),
                    _ => {}
                }
            }
        }
    }
    assert_eq!(rows, [(0, StopKind::Panic), (4, StopKind::HardFault)], "the new stops' rows, once each");
    assert_eq!((stored.stops_of(StopKind::Panic), stored.stops_of(StopKind::HardFault)), (1, 1));
}

/// A new stop kept as the earlier behind a repeat of the stored history's newest (here an NMI
/// on a supply under the PVD level, then the loop's panic 20 s into every boot) is stored at
/// once by the first boot on a good supply, not behind the hold-off: there it waited for a boot
/// that outlasts the minute, in RAM only, and a power cut meanwhile lost it. Once stored, the
/// loop's panic alone waits again, so the loop does not write at every boot.
#[test]
fn a_new_stop_kept_as_the_earlier_reaches_the_record_before_the_next_stop() {
    use crate::failsafe::{nmi_info, panic_info, ResetRecords, StopKind};
    use crate::persist::{PendingSaves, Recorder, WriteGate};
    let panic = panic_info("src/step.rs", 417);
    let mut stored = Recorder::new(HistoryRecord::EMPTY, 360)
        .note_boot(ResetCause::Other, &Stops { earlier: None, latest: Some(panic), fresh: true });
    let mut ram = ResetRecords::EMPTY;
    ram.record(&nmi_info(0, 0));
    let mut writes = Vec::new();
    for n in 0..5 {
        let stops = ram.boot(ResetCause::Other);
        let mut app = App::new(config(), &Boot { history: stored, stops, ..boot() });
        let (mut gate, mut pending) = (WriteGate::firmware(), PendingSaves::EMPTY);
        while let Some(s) = app.next_save() {
            pending.put(s);
        }
        // The first boot's supply is under the PVD level; the panic comes 20 s into each.
        for t in (0..20_000).step_by(10_000) {
            gate.note_supply(t, n > 0);
            while let Some(s) = pending.next(&gate, t) {
                if let Save::History(h) | Save::AlarmHistory(h) = s {
                    stored = h;
                    writes.push(n);
                    ram.stored();
                }
            }
        }
        ram.record(&panic);
    }
    assert_eq!(writes, [1], "the first boot on a good supply, then the loop behind the hold-off");
    assert_eq!((stored.stops_of(StopKind::Nmi), stored.stops_of(StopKind::Panic)), (1, 2));
}

/// A boot that hangs before its control loop (in the clocks, in a flash restore) is reset by
/// the watchdog, again and again while the cause lasts; the stall check is not armed yet and no
/// stop path runs. The phase each boot leaves in a reset-surviving word
/// ([`crate::failsafe::ResetRecords::enter`]) makes the first boot that gets through store
/// a `control_stall` stop naming the phase, at once, even with the alarm's latch already set:
/// before, it found only a watchdog reset, stored behind the hold-off (and not at all if it hung
/// again within the minute), and the record did not say the board had looped.
#[test]
fn a_watchdog_loop_before_the_control_loop_reaches_the_record() {
    use crate::failsafe::{boot_stall, BootPhase, ResetRecords, StopKind};
    use crate::persist::LastStop;
    let stored = HistoryRecord::EMPTY.with_carried(true, false);
    // Each boot of the loop marks Board, then Restore, and hangs there: no stop path runs, so no
    // stop is recorded, and the word says Restore at every watchdog reset. The cause goes away:
    // the next boot gets through and reads it.
    let mut ram = ResetRecords::EMPTY;
    ram.enter(BootPhase::Board);
    ram.enter(BootPhase::Restore);
    let stops = ram.boot(ResetCause::Watchdog);
    assert_eq!(stops, Stops { earlier: None, latest: Some(boot_stall(BootPhase::Restore)), fresh: true });
    let mut b = Bench::new(&Boot { history: stored, reset: ResetCause::Watchdog, stops, ..boot() });
    let first = b.run(1);
    assert!(first.step.events.iter().any(|e| e.kind == EventKind::BoardFault(StopKind::ControlStall)));
    let h = b.saves.iter().find_map(|s| match s {
        Save::AlarmHistory(h) => Some(*h),
        _ => None,
    });
    let h = h.unwrap_or_else(|| panic!("stored at once: {:?}", b.saves));
    assert_eq!(h.last_stop, stops.latest.as_ref().map(LastStop::from));
    assert_eq!((h.stops_of(StopKind::ControlStall), h.resets_by(ResetCause::Watchdog)), (1, 1));
    // The same loop again later waits for the hold-off, as every repeated stop does.
    let again = Boot { history: h, reset: ResetCause::Watchdog, stops, ..boot() };
    assert!(matches!(again.history_save(h), Save::History(_)));
    // Without the marker, the watchdog reset alone: behind the hold-off.
    let bare = Boot { history: stored, reset: ResetCause::Watchdog, ..boot() };
    assert!(matches!(bare.history_save(stored), Save::History(_)));
}

/// A stop, then a boot that hangs before its history is stored (here in the flash restore):
/// the boot that gets through stores both, the stop first, the hang as the newest. Before, the
/// boot that took the stop cleared it from RAM as it read it, and the hang's boot found only
/// the hang: the stop was in no record.
#[test]
fn a_stop_and_the_hang_of_the_boot_that_took_it_both_reach_the_record() {
    use crate::failsafe::{boot_stall, panic_info, BootPhase, ResetRecords, StopKind};
    use crate::persist::LastStop;
    let panic = panic_info("src/step.rs", 417);
    let mut ram = ResetRecords::EMPTY;
    ram.record(&panic);
    // The boot after the panic reads it, counts it, and hangs in the restore before any store.
    assert_eq!(ram.boot(ResetCause::Other), Stops { earlier: None, latest: Some(panic), fresh: true });
    ram.enter(BootPhase::Restore);
    // The watchdog resets it; the next boot gets through.
    let stops = ram.boot(ResetCause::Watchdog);
    let mut b = Bench::new(&Boot { reset: ResetCause::Watchdog, stops, ..boot() });
    let first = b.run(1);
    let faults: Vec<_> = first
        .step
        .events
        .iter()
        .filter_map(|e| match e.kind {
            EventKind::BoardFault(k) => Some(k),
            _ => None,
        })
        .collect();
    assert_eq!(faults, [StopKind::Panic, StopKind::ControlStall]);
    let h = b.saves.iter().find_map(|s| match s {
        Save::AlarmHistory(h) => Some(*h),
        _ => None,
    });
    let h = h.unwrap_or_else(|| panic!("stored at once: {:?}", b.saves));
    assert_eq!((h.stops_of(StopKind::Panic), h.stops_of(StopKind::ControlStall)), (1, 1));
    assert_eq!(h.last_stop, Some(LastStop::from(&boot_stall(BootPhase::Restore))));
    // Once stored, the next boot finds neither.
    ram.stored();
    assert_eq!(ram.boot(ResetCause::Other), Stops::default());
}

/// The flash failing: the third store in a row that fails latches the indicator, logs one
/// `store_failed` row and shows `flash=failing` in `status`, once per run of failures; a store
/// that succeeds ends the run.
#[test]
fn a_flash_that_keeps_failing_latches_the_indicator_once_per_run() {
    let mut b = Bench::new(&boot());
    let rows = |b: &Bench| {
        b.saves.iter().filter(|s| matches!(s, Save::Log(LogEntry::Event { kind: EventKind::StoreFailed, .. }))).count()
    };
    for n in [0, 1, 2] {
        b.app.note_store_failures(n);
        assert_eq!(b.run(1).alarm, Indication::Off, "{n} in a row");
        assert_eq!(b.field("flash"), "ok");
    }
    for n in [3, 4, 9] {
        b.app.note_store_failures(n);
        assert_eq!(b.run(1).alarm, Indication::Unacknowledged, "{n} in a row");
        assert_eq!(b.field("flash"), "failing");
    }
    assert_eq!(rows(&b), 1);
    b.app.acknowledge();
    b.app.note_store_failures(10);
    assert_eq!(b.run(1).alarm, Indication::Off, "acknowledged, the same run");
    b.app.note_store_failures(0);
    b.run(1);
    assert_eq!(b.field("flash"), "ok");
    b.app.note_store_failures(3);
    assert_eq!(b.run(1).alarm, Indication::Unacknowledged, "a new run");
    assert_eq!(rows(&b), 2);
}

/// A records region erased because the storage layer found it corrupt: the settings, the
/// calibration that runs and the cabinet model, which nothing stores again unless they change,
/// are queued once more with the history; a board that never stored settings stores none. An
/// accepted calibration is stored in the calibration record as well as in the settings.
#[test]
fn an_erased_records_region_gets_the_settings_and_models_back() {
    let mut b = Bench::new(&boot());
    b.run(1);
    b.saves.clear();
    b.app.records_erased();
    b.drain();
    assert!(
        matches!(b.saves[..], [Save::Calibration(TwoPoint::IDENTITY), Save::History(_)]),
        "nothing set yet: {:?}",
        b.saves
    );
    // The calibration that runs is stored again too: an image without the interface reads it.
    assert_eq!(b.send("set cal_ice 0.5,0.0"), "ok\r\n");
    let cal = b.app.carrier().config().cal;
    assert!(b.saves.contains(&Save::Calibration(cal)), "with the settings: {:?}", b.saves);
    b.saves.clear();
    b.app.records_erased();
    b.drain();
    assert!(b.saves.contains(&Save::Calibration(cal)), "{:?}", b.saves);
    assert_eq!(b.send("set setpoint_c 5.5"), "ok\r\n");
    assert_eq!(b.send("set model -1.904667,0.904945;-0.012378,-0.0001;6"), "ok\r\n");
    b.saves.clear();
    b.app.records_erased();
    b.drain();
    let settings = b.saves.iter().find_map(|s| match s {
        Save::Settings(s) => Some(*s),
        _ => None,
    });
    assert_eq!(settings.map(|s| s.setpoint_c), Some(5.5), "{:?}", b.saves);
    #[cfg(feature = "holdover")]
    assert!(b.saves.iter().any(|s| matches!(s, Save::Cabinet(_))), "{:?}", b.saves);
    assert!(b.saves.iter().any(|s| matches!(s, Save::History(_))));
}

#[test]
fn the_log_gets_intervals_events_and_continues_its_record_time_after_a_reset() {
    let mut b = Bench::new(&Boot { log_last_s: 86_400, reset: ResetCause::BrownOut, ..boot() });
    b.run(91);
    let log: Vec<LogEntry> = b
        .saves
        .iter()
        .filter_map(|s| match s {
            Save::Log(e) => Some(*e),
            _ => None,
        })
        .collect();
    assert_eq!(log.first(), Some(&LogEntry::Event { t_s: 86_401, kind: EventKind::Restarted(ResetCause::BrownOut) }));
    let intervals: Vec<u32> = log.iter().filter(|e| matches!(e, LogEntry::Interval { .. })).map(|e| e.t_s()).collect();
    // Record time starts at 86 401 s; intervals end on multiples of 300 s.
    assert_eq!(intervals, [86_700, 87_000, 87_300]);
    assert!(log.windows(2).all(|w| w[0].t_s() <= w[1].t_s()), "in time order");
}

#[test]
fn status_shows_an_accepted_setpoint_at_once() {
    let mut b = bench_under_pi();
    b.run(30);
    assert_eq!(b.send("set setpoint_c 5.5"), "ok\r\n");
    // Before the next sample (up to Ts later): the setpoint in force, as `get` shows it.
    assert_eq!(b.field("setpoint_c"), "5.50");
    b.run(1);
    assert_eq!(b.field("setpoint_c"), "5.50");
}

#[test]
fn status_names_no_law_while_the_step_holds_the_outputs() {
    let mut b = Bench::new(&boot());
    b.run(30);
    assert_eq!((b.field("controller").as_str(), b.field("mode").as_str()), ("gpc", "normal"));
    assert_ne!(b.field("adaptive"), "-");
    // A sensor fault (the reference conversions out of their window): cooling held off, no law
    // runs.
    for _ in 0..3 {
        let counts = counts_at(b.load_c);
        b.app.sample(&SampleIn { t_ms: b.t_ms, counts, reference_ok: false, board: Default::default() });
        b.t_ms += 10_000;
    }
    assert_eq!(b.field("mode"), "sensor_fault");
    assert_eq!(b.field("alarm"), "not_in_control");
    assert_eq!((b.field("controller").as_str(), b.field("adaptive").as_str()), ("-", "-"));
    // The setting is unchanged: `get` says which law resumes.
    assert!(b.send("get").contains("controller=gpc\r\n"));
    b.run(3);
    assert_eq!(b.field("mode"), "normal");
    assert_eq!(b.field("controller"), "gpc");
    assert_ne!(b.field("adaptive"), "-");
}

#[test]
fn resets_counts_the_restarts_after_the_boot_that_began_the_record() {
    // A new board: its first boot (a power-on; the pin reset after flashing) is no reset.
    for reset in [ResetCause::Other, ResetCause::BrownOut] {
        let mut b = Bench::new(&Boot { reset, ..boot() });
        b.run(1);
        assert_eq!(b.field("resets"), "0", "{reset:?}");
    }
    // The record it stored at boot counts that boot; each later boot is a restart.
    let mut b = Bench::new(&boot());
    b.run(1);
    let stored = b
        .saves
        .iter()
        .rev()
        .find_map(|s| match s {
            Save::History(h) => Some(*h),
            _ => None,
        })
        .expect("the boot stores the history");
    let mut b = Bench::new(&Boot { history: stored, reset: ResetCause::BrownOut, ..boot() });
    b.run(1);
    assert_eq!(b.field("resets"), "1");
    let mut again = stored;
    again.note_reset(ResetCause::BrownOut);
    let mut b = Bench::new(&Boot { history: again, reset: ResetCause::Watchdog, ..boot() });
    b.run(1);
    assert_eq!(b.field("resets"), "2");
}

#[test]
fn help_lists_every_command_and_unknown_ones_point_to_it() {
    let mut b = Bench::new(&boot());
    let help = b.send("help");
    for cmd in ["status", "get", "set setpoint_c", "set controller", "set cal_ice", "ack", "history", "identify"] {
        assert!(help.contains(cmd), "{cmd}");
    }
    assert!(help.ends_with("ok\r\n"));
    assert_eq!(b.send("reboot"), "err line: unknown command (try help)\r\n");
    assert_eq!(b.send(""), "");
    let mut out = String::new();
    assert_eq!(b.app.handle("history 600", &mut out), Handled::History { since_s: 600 });
    assert_eq!(out, "", "the glue streams the rows");
}

use std::format;
use std::string::ToString;

/// The interface sweep's two calibration writes: each point was accepted against the other's
/// value, and together they read a −4.4 °C load as 5.00 °C. The second is refused now, and a
/// calibration is refused while a commissioning records readings through the present one.
#[test]
fn a_calibration_that_moves_the_reading_by_degrees_or_lands_mid_commissioning_is_refused() {
    let mut b = Bench::new(&boot());
    b.run(10);
    assert_eq!(b.send("set cal_warm 100,100"), "ok\r\n");
    let before = *b.app.settings();
    assert_eq!(
        b.send("set cal_ice 0,9"),
        "err cal_ice: the points move a reading between 0 and 10 °C by more than 1.5 °C\r\n"
    );
    assert_eq!(*b.app.settings(), before);
    // The accepted point moved the load: a commissioning waits until the carrier has held it.
    assert!(b.send("identify").starts_with("err identify: the carrier has not held its setpoint long enough"));
    b.run(usize::from(SETTLE_SAMPLES));
    assert_eq!(b.send("identify"), "ok\r\n");
    b.run(3);
    assert_eq!(b.send("set cal_ice 0.5,0"), "err cal_ice: commissioning is running (identify abort)\r\n");
    assert_eq!(*b.app.settings(), before);
    assert_eq!(b.send("identify abort"), "ok\r\n");
    assert_eq!(b.send("set cal_ice 0.5,0"), "ok\r\n");
}

/// The record is a ring: whatever is logged pushes its oldest entries out. 42 600 `ack`s with
/// no alarm pending once left 9 h of a 3.6-day record; an `ack` with nothing to acknowledge
/// and a `set` to the value a setting already has are said `ok` and record nothing.
#[test]
fn repeated_acks_and_unchanged_settings_leave_the_record_alone() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let saves = b.saves.len();
    for _ in 0..100 {
        assert_eq!(b.send("ack"), "no alarm\r\nok\r\n");
        assert_eq!(b.send("set setpoint_c 4"), "ok\r\n");
        assert_eq!(b.send("set controller gpc"), "ok\r\n");
    }
    assert_eq!(b.saves.len(), saves, "nothing stored or logged");
    assert_eq!(b.app.settings().seq, 0);
    assert_eq!(b.send("set ack 0"), "err ack: usage: set ack 1, or ack\r\n");
    // A change is still a change.
    assert_eq!(b.send("set setpoint_c 5"), "ok\r\n");
    assert_eq!(b.setting_logs(), [SettingKey::Setpoint]);
}

/// Found by `tests/iface_fuzz.rs`: `set model` of the cabinet model the board already has, which
/// the self-tuner does not take (b1 > 0), changes nothing, yet it was logged and its record
/// queued for flash again at every repeat. A model the self-tuner takes restarts it from the
/// model each time, which is a change, and is recorded.
#[test]
fn a_repeated_cabinet_model_is_neither_stored_nor_recorded_again() {
    let mut b = Bench::new(&boot());
    b.run(10);
    for _ in 0..3 {
        assert_eq!(b.send(&format!("set model {PARALLEL_LAGS}")), "ok\r\n");
    }
    assert_eq!(b.setting_logs(), [SettingKey::Model]);
    #[cfg(feature = "holdover")]
    assert_eq!(b.saves.iter().filter(|s| matches!(s, Save::Cabinet(_))).count(), 1);
    assert_eq!(b.field("cabinet_a"), "-1.938996,0.939181");
    let control = "-1.859405,0.859802;-0.014713,-0.003021;8";
    for _ in 0..2 {
        assert_eq!(b.send(&format!("set model {control}")), "ok\r\n");
    }
    assert_eq!(b.setting_logs(), [SettingKey::Model; 3]);
    // Back to the first: a change of the cabinet model.
    assert_eq!(b.send(&format!("set model {PARALLEL_LAGS}")), "ok\r\n");
    assert_eq!(b.setting_logs(), [SettingKey::Model; 4]);
}

/// A bench 10 samples in, whose sensor broke for 3 samples and came back: the indicator latched.
fn bench_with_a_latched_sensor_fault() -> Bench {
    let mut b = Bench::new(&boot());
    b.run(10);
    let load = b.load_c;
    b.load_c = 400.0;
    b.run(3);
    b.load_c = load;
    b
}

/// The board's cold-chain record takes no temperature through a sensor fault: the step's last
/// good reading, held for the controller, is no measurement. 12 h of a sensor fault with the
/// load at 12 °C were recorded as 12 h in range at the held 4 °C with no `heat_10h`; now the fault's time is cut out, as `hter monitor` cuts it from a log,
/// and the hour with readings at 12 °C after it is the record's only time above 8 °C.
#[test]
fn the_record_takes_no_temperature_through_a_sensor_fault() {
    let mut b = Bench::new(&boot());
    b.dither = true;
    b.run(30);
    let before = b.app.recorder().history();
    // The reference conversions out of their window: no reading from the first sample on.
    b.load_c = 12.0;
    for _ in 0..12 * 360 {
        let counts = counts_at(b.load_c);
        let out = b.app.sample(&SampleIn { t_ms: b.t_ms, counts, reference_ok: false, board: Default::default() });
        b.t_ms += 10_000;
        assert_eq!(out.step.mode, crate::step::Mode::SensorFault);
        assert!(out.raised.iter().all(Option::is_none), "no alarm from a held reading");
    }
    let fault = b.app.recorder().history();
    // The samples' interval before the fault belongs to the last reading (one sample period).
    assert!(fault.recorded_s - before.recorded_s <= 10, "{} s recorded in the fault", fault.recorded_s);
    assert_eq!((fault.below_2_s, fault.above_8_s, fault.excursions), (0, 0, 0));
    // The sensor back, the load at 12 °C for an hour: an hour above 8 °C, no more.
    b.load_c = 12.0;
    b.pinned_c = Some(12.0);
    b.run(360);
    let after = b.app.recorder().history();
    assert!((3_500..=3_600).contains(&after.above_8_s), "{} s above 8 °C", after.above_8_s);
    assert!((3_500..=3_700).contains(&(after.recorded_s - fault.recorded_s)), "{} s", after.recorded_s);
    assert_eq!(after.alarms_of(crate::coldchain::AlarmKind::Heat10h), 0);
}

/// With an alarm latched, `ack` acknowledges it and is recorded, once: a second `ack` before the
/// next sample has nothing left to acknowledge.
#[test]
fn an_ack_with_an_alarm_latched_is_applied_and_recorded_once() {
    let mut b = bench_with_a_latched_sensor_fault();
    let out = b.run(30);
    assert_eq!(out.alarm, Indication::Unacknowledged, "{out:?}");
    assert_eq!(b.send("ack"), "ok\r\n");
    assert_eq!(b.send("ack"), "no alarm\r\nok\r\n");
    assert_eq!(b.setting_logs(), [SettingKey::Ack]);
    assert_eq!(b.run(1).alarm, Indication::Off);
}

/// `t_s` from the integer clock: through f32 it read 8025510.4 on a 10 s grid after 93 days,
/// and `-` after 6 years.
#[test]
fn status_time_stays_exact_after_months_and_years() {
    let mut b = Bench::new(&boot());
    b.t_ms = 8_025_510_000;
    b.run(1);
    assert_eq!(b.field("t_s"), "8025510.0");
    b.t_ms = 250_000_000_000;
    b.run(1);
    assert_eq!(b.field("t_s"), "250000000.0");
}

/// The module-side sense reaches the step through the board's sample: the modules' own Seebeck
/// voltage for an hour is no short; the supply across them in the window, twice, is one.
#[cfg(feature = "module-sense")]
#[test]
fn the_apps_sample_carries_the_module_side_sense_to_the_step() {
    let mut b = Bench::new(&boot());
    // PI holds a steady duty on this bench's plant (the self-tuner, on a start model of another
    // plant, swings it to full cooling, where the window tells nothing).
    assert_eq!(b.send("set controller pi"), "ok\r\n");
    b.module_v = Some(2.5);
    for _ in 0..360 {
        let out = b.run(1);
        assert!(out.step.events.iter().all(|e| e.kind != EventKind::SsrStuckOn), "t = {} ms", b.t_ms);
    }
    // A shorted SSR: the supply (12 V, above the 6 V limit without a supply reading) in the window.
    b.module_v = Some(12.0);
    let first = b.run(1);
    assert_eq!(first.step.mode, crate::step::Mode::Normal, "one reading is not a short");
    assert!(first.step.supply_enable);
    assert!(first.step.duty.get() < 0.9, "the SSR must be commanded off in the window: {:?}", first.step.duty);
    let second = b.run(1);
    assert!(second.step.events.iter().any(|e| e.kind == EventKind::SsrStuckOn), "{:?}", second.step.events);
    assert_eq!(second.step.mode, crate::step::Mode::LimpHome);
}

/// A shorted SSR is stored with the history at once, and the boots after it limp home from
/// their first sample (a short does not heal in a brown-out, a watchdog bite, a fail-safe stop
/// or a pin reset, which an NRST glitch or a debugger gives too); only a service reset (the
/// acknowledge button held through a person's reset, after the SSR was replaced) hands the
/// modules back to the controller. Before, every boot handed them back: full cooling until the
/// checks found the short again; then a pin reset alone did.
#[cfg(feature = "module-sense")]
#[test]
fn a_shorted_ssr_is_remembered_until_a_service_reset() {
    let mut b = Bench::new(&boot());
    assert_eq!(b.send("set controller pi"), "ok\r\n");
    b.run(30);
    b.saves.clear();
    b.module_v = Some(12.0);
    let out = b.run(2);
    assert_eq!(out.step.mode, crate::step::Mode::LimpHome);
    // Stored at once (past the write gate's hold-off), with the short.
    let stored = b.saves.iter().find_map(|s| match s {
        Save::AlarmHistory(h) if h.ssr_shorted() => Some(*h),
        _ => None,
    });
    let stored = stored.unwrap_or_else(|| panic!("the short is stored at once: {:?}", b.saves));
    assert_eq!(HistoryRecord::decode(&stored.encode()), Ok(stored));
    b.saves.clear();
    b.run(5);
    let again = b.saves.iter().any(|s| matches!(s, Save::AlarmHistory(_) | Save::History(_)));
    assert!(!again, "stored once: {:?}", b.saves);

    // The SSR is still shorted: with the modules cooling flat out whatever the duty, the boots
    // that keep the short limp home from the first sample, supply open; a service reset hands
    // the modules to the controller. The button held by chance through a watchdog bite, a
    // fail-safe stop or a power cut is no service reset.
    let halt = crate::failsafe::StopInfo::new(crate::failsafe::StopKind::ControlStall, 0, 0, 12_000);
    for (reset, fault, service, limps) in [
        (ResetCause::BrownOut, None, false, true),
        (ResetCause::Watchdog, None, false, true),
        (ResetCause::Other, Some(halt), false, true),
        (ResetCause::Other, None, false, true),
        (ResetCause::Watchdog, None, true, true),
        (ResetCause::Other, Some(halt), true, true),
        (ResetCause::BrownOut, None, true, true),
        (ResetCause::Other, None, true, false),
    ] {
        let mut next = Bench::new(&Boot {
            history: stored,
            reset,
            stops: Stops { earlier: None, latest: fault, fresh: fault.is_some() },
            button_held: service,
            ..boot()
        });
        next.load_c = 5.0;
        let first = next.run(1);
        let what = format!("{reset:?} {:?} service {service}", fault.map(|f| f.kind));
        assert_eq!(first.step.mode == crate::step::Mode::LimpHome, limps, "{what}: {:?}", first.step.mode);
        if limps {
            assert!(!first.step.supply_enable && first.step.duty.get() == 0.0, "{what}: supply open first");
            assert!(next.app.carrier().ssr_shorted(), "{what}");
            // Acknowledged, the indicator stays on through limp home's freeze-guard holds, which
            // report `freeze_guard`: the short is the history's, not this boot's finding (before,
            // the indicator went off there after every restart).
            next.send("ack");
            let run: Vec<_> = (0..40)
                .map(|k| {
                    // A load falling 0.6 °C a minute, from 5 °C to 2.2 °C: the guard's look-ahead.
                    next.pinned_c = Some((5.0 - 0.1 * k as f32).max(2.2));
                    next.run(1)
                })
                .collect();
            assert!(
                run.iter().any(|o| o.step.mode == crate::step::Mode::FreezeGuard),
                "{what}: a hold: {:?}",
                run.iter().map(|o| (o.step.mode, o.step.temp_c.0)).collect::<Vec<_>>()
            );
            assert!(run.iter().all(|o| o.alarm == Indication::NotInControl), "{what}: {:?}", run.last());
            next.pinned_c = None;
        }
        // What the boot stores carries the short on, or its clearing, at once and on record.
        let boot_history = next.saves.iter().find_map(|s| match s {
            Save::History(h) | Save::AlarmHistory(h) => Some(*h),
            _ => None,
        });
        assert_eq!(boot_history.map(|h| h.ssr_shorted()), Some(limps), "{what}");
        let cleared = service_logged(&next);
        if limps {
            assert_eq!(cleared, None, "{what}");
        } else {
            assert!(next.saves.iter().any(|s| matches!(s, Save::AlarmHistory(h) if !h.ssr_shorted())), "{what}");
            assert_eq!(cleared, Some([0.0, 1.0]), "{what}");
        }
    }
}

/// What a refusal quotes is the value as it was typed: `2.4999` was answered "2.50 is outside
/// 2.5…7.5", a value the range accepts.
#[test]
fn a_refusal_quotes_the_value_as_it_was_typed() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let before = *b.app.settings();
    for (line, reply) in [
        ("set setpoint_c 2.4999", "err setpoint_c: 2.4999 is outside 2.5…7.5\r\n"),
        ("set setpoint_c 7.5001", "err setpoint_c: 7.5001 is outside 2.5…7.5\r\n"),
        ("set setpoint_c 2.4", "err setpoint_c: 2.4 is outside 2.5…7.5\r\n"),
        ("set setpoint_c -0.5", "err setpoint_c: -0.5 is outside 2.5…7.5\r\n"),
        ("set cal_ice 0.00,-50.004", "err cal_ice: -50.004 is outside -50.0…100.0\r\n"),
        ("set cal_warm 100.001,100", "err cal_warm: 100.001 is outside -50.0…100.0\r\n"),
    ] {
        assert_eq!(b.send(line), reply, "{line}");
    }
    assert_eq!(*b.app.settings(), before);
    assert!(b.setting_logs().is_empty());
}

/// The model's delay K is a whole number of samples: `5.5` was answered "outside 1.0…10.0".
#[test]
fn a_model_delay_that_is_not_a_whole_number_of_samples_is_refused_as_such() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let m = "-1.859405,0.859802;-0.014713,-0.003021";
    let k = |k: &str| format!("err model: K must be a whole number of samples in 1…10, not {k}\r\n");
    for bad in ["5.5", "0", "11", "-3", "0.5", "x", "1e1"] {
        assert_eq!(b.send(&format!("set model {m};{bad}")), k(bad), "{bad}");
    }
    assert!(b.setting_logs().is_empty());
    // A whole number written with zeros after the point is one.
    assert_eq!(b.send(&format!("set model {m};8.00")), "ok\r\n");
    assert_eq!(b.field("model_k"), "8");
}

/// Seven digits were a limit on how a value was written, not on the value: `5.00000000` (eight)
/// and `004.5` were "not a decimal number". Zeros before the first significant digit and after
/// the last decimal are no digits; more than seven significant digits is refused saying so.
#[test]
fn zeros_that_change_nothing_do_not_count_and_the_digit_limit_is_named() {
    let mut b = Bench::new(&boot());
    b.run(10);
    assert_eq!(b.send("set setpoint_c 5.00000000"), "ok\r\n");
    assert_eq!(b.app.settings().setpoint_c, 5.0);
    assert_eq!(b.send("set setpoint_c 0004.50"), "ok\r\n");
    assert_eq!(b.app.settings().setpoint_c, 4.5);
    assert_eq!(b.send("set cal_ice 0.500000000,0000.00000"), "ok\r\n");
    assert_eq!(b.send("set model -1.8594050000,0.859802;-0.014713,-0.0030210000;8"), "ok\r\n");
    assert_eq!(b.field("model_a"), "-1.859405,0.859802");
    assert_eq!(b.field("cabinet_b"), "-0.014713,-0.003021");
    let saves = b.saves.len();
    assert_eq!(
        b.send("set model -1.859405,0.859802;-12.345678,-0.003021;8"),
        "err model: -12.345678 has more than 7 significant digits\r\n"
    );
    assert_eq!(b.saves.len(), saves);
}

/// A value finer than its setting is shown and recorded was accepted and invisible: `set
/// setpoint_c 5.001` ran 5.001 °C while `status`, `get` and the record's event said 5.00. Every
/// numeric setting refuses decimals past its step, naming the step, and changes nothing.
#[test]
fn a_value_finer_than_its_settings_step_is_refused_naming_the_step() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let before = *b.app.settings();
    let model_before = (b.field("model_a"), b.field("model_b"), b.field("cabinet_a"));
    for (line, reply) in [
        ("set setpoint_c 5.001", "err setpoint_c: 5.001 is finer than the 0.01 °C step (at most 2 decimals)\r\n"),
        (
            "set setpoint_c 4.0000001",
            "err setpoint_c: 4.0000001 is finer than the 0.01 °C step (at most 2 decimals)\r\n",
        ),
        ("set cal_ice 0.125,0.00", "err cal_ice: 0.125 is finer than the 0.01 °C step (at most 2 decimals)\r\n"),
        ("set cal_warm 25.00,25.005", "err cal_warm: 25.005 is finer than the 0.01 °C step (at most 2 decimals)\r\n"),
        (
            "set model -1.8594051,0.859802;-0.014713,-0.003021;8",
            "err model: -1.8594051 is finer than the 0.000001 step (at most 6 decimals)\r\n",
        ),
        (
            "set model -1.859405,0.859802;-0.014713,-0.0030214;8",
            "err model: -0.0030214 is finer than the 0.000001 step (at most 6 decimals)\r\n",
        ),
    ] {
        assert_eq!(b.send(line), reply, "{line}");
    }
    assert_eq!(*b.app.settings(), before);
    assert!(b.setting_logs().is_empty(), "nothing recorded");
    assert_eq!((b.field("model_a"), b.field("model_b"), b.field("cabinet_a")), model_before);
    // At the step: used, shown and recorded as typed.
    assert_eq!(b.send("set setpoint_c 4.01"), "ok\r\n");
    b.run(1);
    assert_eq!(b.field("setpoint_c"), "4.01");
    assert!(b.send("get").contains("setpoint_c=4.01\r\n"));
    let Some(Save::Log(e)) = b.saves.iter().rev().find(|s| matches!(s, Save::Log(LogEntry::Setting { .. }))) else {
        panic!("the setting is logged")
    };
    let mut row = String::new();
    crate::persist::log::write_csv_row(e, &mut row).unwrap();
    assert!(row.contains("set:setpoint_c=4.01"), "{row}");
}

/// On-Off is settable (SPEC §8) but no field controller: its limit cycle on these carriers is
/// up to 3 °C peak to peak and leaves 2–8 °C (1.71 °C at setpoint 3.5 °C and 15 °C ambient).
/// Its acceptance says so in a data line before `ok`, which a host passes on.
#[test]
fn switching_to_on_off_is_accepted_with_a_warning_line() {
    let mut b = Bench::new(&boot());
    b.run(10);
    let reply = b.send("set controller onoff");
    let lines: Vec<&str> = reply.split("\r\n").collect();
    assert_eq!(lines.len(), 3, "{reply}");
    assert!(lines[0].starts_with("warning: onoff is a comparison baseline"), "{reply}");
    assert!(lines[0].contains("can leave 2-8 °C") && lines[0].contains("gpc is the field controller"), "{reply}");
    assert_eq!(&lines[1..], ["ok", ""]);
    assert_eq!(b.field("controller"), "onoff");
    assert_eq!(b.setting_logs(), [SettingKey::Controller]);
    // The other laws say nothing more than `ok`.
    assert_eq!(b.send("set controller pi"), "ok\r\n");
    assert_eq!(b.send("set controller gpc"), "ok\r\n");
}

/// A boot after a fail-safe stop (here the stall check's, which resets by software: the reset
/// flags say `Other`) shows the indicator until someone acknowledges it, as a boot after a
/// watchdog bite does; a plain power-on does not.
#[test]
fn a_boot_after_a_fail_safe_stop_latches_the_indicator() {
    use crate::failsafe::{StopInfo, StopKind};
    let stall = StopInfo::new(StopKind::ControlStall, 0, 0, 25_000);
    let mut b = Bench::new(&Boot { stops: Stops { earlier: None, latest: Some(stall), fresh: true }, ..boot() });
    assert_eq!(b.run(1).alarm, Indication::Unacknowledged);
    assert_eq!(b.run(30).alarm, Indication::Unacknowledged);
    assert_eq!(b.send("ack"), "ok\r\n");
    assert_eq!(b.run(1).alarm, Indication::Off);
    let mut b = Bench::new(&Boot { reset: ResetCause::BrownOut, ..boot() });
    assert_eq!(b.run(30).alarm, Indication::Off);
}

/// The newest history the bench's app handed over for flash.
fn stored_history(b: &Bench) -> HistoryRecord {
    b.saves
        .iter()
        .rev()
        .find_map(|s| match s {
            Save::History(h) | Save::AlarmHistory(h) => Some(*h),
            _ => None,
        })
        .expect("a history was stored")
}

/// The record's `service_reset` entry the bench queued, if any: what a service reset cleared
/// (the offset, °C, 0 if none; 1 if the SSR's short).
fn service_logged(b: &Bench) -> Option<[f32; 2]> {
    b.saves.iter().find_map(|s| match s {
        Save::Log(LogEntry::Setting { key: SettingKey::Service, value, .. }) => Some(*value),
        _ => None,
    })
}

/// A restart is no acknowledgement: a fault nobody has seen (a sensor that failed and came
/// back) keeps the indicator on after a brown-out, from the history the boot reads; the boot
/// after an `ack` is quiet. The latch was RAM alone, and the first sample after the restart
/// showed `off`.
#[test]
fn a_restart_keeps_an_unacknowledged_alarm_on() {
    let mut b = bench_with_a_latched_sensor_fault();
    assert_eq!(b.run(30).alarm, Indication::Unacknowledged);
    let stored = stored_history(&b);
    assert!(stored.unacknowledged());
    let mut again = restarted(&b, stored);
    assert_eq!(again.run(1).alarm, Indication::Unacknowledged);
    assert_eq!(again.run(30).alarm, Indication::Unacknowledged);
    assert_eq!(again.send("ack"), "ok\r\n");
    assert_eq!(again.run(1).alarm, Indication::Off);
    let acked = stored_history(&again);
    assert!(!acked.unacknowledged());
    let mut third = restarted(&again, acked);
    assert_eq!(third.run(30).alarm, Indication::Off);
}

/// An `ack` with nothing latched while the indicator is on for what is true now says so: it
/// said `no alarm` with `status` at `alarm=not_in_control` (a sensor fault) or
/// `alarm=out_of_range`.
#[test]
fn an_ack_under_a_present_danger_says_the_alarm_stays() {
    let mut b = Bench::new(&boot());
    b.run(10);
    b.load_c = 400.0;
    assert_eq!(b.run(3).alarm, Indication::NotInControl);
    assert_eq!(b.send("ack"), "ok\r\n");
    assert_eq!(b.run(1).alarm, Indication::NotInControl);
    assert_eq!(b.send("ack"), "alarm=not_in_control stays on while it lasts\r\nok\r\n");
    assert_eq!(b.setting_logs(), [SettingKey::Ack], "recorded once");
}

/// A bench holding 4 °C (dither, PI) whose RTD lead stepped 1.5 °C warm 10 samples ago: the
/// offset watch has measured the step and subtracts it.
fn bench_with_a_compensated_lead() -> Bench {
    let mut b = holding_with_dither();
    b.lead_c = 1.5;
    let mut events = Vec::new();
    for _ in 0..10 {
        events.extend(b.run(1).step.events.iter().map(|e| e.kind));
    }
    assert!(events.contains(&EventKind::SensorOffset), "{events:?}");
    b
}

/// The board after a brown-out of `b`'s, from the settings and the history `b` handed over for
/// flash, in front of the same load, lead and plant.
fn restarted(b: &Bench, history: HistoryRecord) -> Bench {
    booted_after(b, &Boot { settings: Some(*b.app.settings()), history, reset: ResetCause::BrownOut, ..boot() })
}

/// The board booted from `boot` after `b`'s, in front of the same load, lead and plant.
fn booted_after(b: &Bench, boot: &Boot) -> Bench {
    let mut again = Bench::new(boot);
    (again.load_c, again.lead_c, again.dither, again.pipe) = (b.load_c, b.lead_c, b.dither, b.pipe.clone());
    again
}

/// The worst difference of the offset-corrected reading from the load through the app's line
/// over `samples` samples, °C, and the events ([`against_truth`]; the alarm may be on: an
/// offset latches it).
fn reading_error(b: &mut Bench, samples: usize) -> (f32, Vec<EventKind>) {
    let (raw, _, events, _) = against_truth(b, samples);
    (raw, events)
}

/// The sensor offset the board subtracts is stored with the history at once, and the next boot
/// subtracts it from its first sample. It was RAM alone: after a brown-out the lead fault read
/// 1.5 °C warm again, and the board held the load 1.5 °C colder than it showed (`hter sim
/// --fault sensor-offset@3000 --fault brownout@10000`: 2.50 °C true for 3.98 °C read).
#[test]
fn a_restart_keeps_the_sensor_offset_compensated() {
    let b = bench_with_a_compensated_lead();
    let Some(Save::AlarmHistory(stored)) =
        b.saves.iter().rev().find(|s| matches!(s, Save::History(_) | Save::AlarmHistory(_))).copied()
    else {
        panic!("the offset's history is stored past the hold-off")
    };
    assert!((stored.sensor_offset.c() - 1.5).abs() < 0.05, "{:?}", stored.sensor_offset);
    let mut again = restarted(&b, stored);
    let (worst, events) = reading_error(&mut again, 360);
    assert!(worst < 0.05, "the reading is {worst} °C off the load");
    assert!(!events.contains(&EventKind::SensorOffset), "{events:?}");
    assert!((again.load_c - 4.0).abs() < 0.2, "the load at {}", again.load_c);
    // Without it, the same boot reads the lead's 1.5 °C.
    let mut forgot = restarted(&b, stored.with_sensor_offset(crate::persist::SensorOffset::NONE));
    let (worst, _) = reading_error(&mut forgot, 1);
    assert!(worst > 1.4, "{worst}");
}

/// A lead repaired with the RTD unplugged leaves the offset kept (above); on a build without
/// the interface there is no `set sensor_offset_c 0`. A service reset (the acknowledge button
/// held through a reset) clears it on every build: the repaired sensor reads true from the
/// first sample, the history without it is stored at once and the record says what was
/// cleared. A reset alone keeps it.
#[test]
fn a_service_reset_clears_the_sensor_offset_after_a_repair() {
    let mut b = bench_with_a_compensated_lead();
    let stored = stored_history(&b);
    b.lead_c = 0.0;
    let service = Boot { settings: Some(*b.app.settings()), history: stored, button_held: true, ..boot() };
    for (boot, cleared) in [(Boot { button_held: false, ..service }, false), (service, true)] {
        let mut again = booted_after(&b, &boot);
        let (worst, _) = reading_error(&mut again, 1);
        let at_boot = &again.saves;
        let logged = service_logged(&again);
        if cleared {
            assert!(worst < 0.05, "the repaired sensor reads the load: {worst} °C off");
            let first = at_boot.iter().find(|s| matches!(s, Save::History(_) | Save::AlarmHistory(_)));
            assert!(
                matches!(first, Some(Save::AlarmHistory(h)) if h.sensor_offset == crate::persist::SensorOffset::NONE),
                "{first:?}"
            );
            assert!(logged.is_some_and(|v| (v[0] - 1.5).abs() < 0.05 && v[1] == 0.0), "{logged:?}");
        } else {
            assert!((worst - 1.5).abs() < 0.1, "a reset alone keeps it: {worst}");
            assert_eq!(logged, None);
        }
    }
}

/// A service reset after replacing the SSR, on a carrier whose probe lead still reads 1.5 °C
/// warm (compensated months before): the short is forgotten, the offset is not. A restart does
/// not measure an offset again (the watch sees steps, and the first reading already carries
/// it), so forgotten with the lead still damaged, the board held the load 1.5 °C colder than it
/// read for good, the freeze guard blind to it (up to 3 °C: the freezing side). One service
/// reset forgets one repair, the short first; a second one, with no short left, the offset.
#[test]
fn a_service_reset_after_an_ssr_repair_keeps_the_sensor_offset() {
    let b = bench_with_a_compensated_lead();
    let with_short = stored_history(&b).with_carried(false, true);
    let service = |history| Boot { settings: Some(*b.app.settings()), history, button_held: true, ..boot() };
    let mut again = booted_after(&b, &service(with_short));
    let (worst, events) = reading_error(&mut again, 360);
    let load = again.load_c;
    assert!(
        worst < 0.05,
        "the lead still reads warm: the offset must stay subtracted ({worst} °C off, load {load} °C)"
    );
    assert!(!again.app.carrier().ssr_shorted(), "the short is forgotten");
    assert!(!events.contains(&EventKind::SensorOffset), "{events:?}");
    assert_eq!(service_logged(&again), Some([0.0, 1.0]), "the record says the short alone was cleared");
    let kept = stored_history(&again);
    assert!(!kept.ssr_shorted() && (kept.sensor_offset.c() - 1.5).abs() < 0.05, "{kept:?}");

    // The lead repaired too: a second service reset forgets the offset.
    again.lead_c = 0.0;
    let mut third = booted_after(&again, &service(kept));
    let (worst, _) = reading_error(&mut third, 1);
    assert!(worst < 0.05, "the repaired sensor reads the load: {worst} °C off");
    assert!(service_logged(&third).is_some_and(|v| (v[0] - 1.5).abs() < 0.05 && v[1] == 0.0));
}

/// The offset is stored in the channel's terms: a calibration stored after it, and a power cut
/// before the next history, restore it as the board subtracted it through the new line. In the
/// reading's own terms, the new line's gain of 1.05 left 0.075 °C of the 1.5 °C lead in it.
#[test]
fn a_calibration_stored_after_the_offset_restores_it_through_the_new_line() {
    let mut b = bench_with_a_compensated_lead();
    let stored = stored_history(&b);
    assert_eq!(b.send("set cal_warm 25.0,26.25"), "ok\r\n");
    assert!((line(&b).gain - 1.05).abs() < 1e-4);
    let (worst, _) = reading_error(&mut b, 1);
    assert!(worst < 0.03, "through the new line before the cut: {worst}");
    // The history after the change holds the same offset: no write for it.
    assert_eq!(stored_history(&b).sensor_offset, stored.sensor_offset);
    // The cut before any history after the calibration: new settings, the older history.
    let mut again = restarted(&b, stored);
    let (worst, _) = reading_error(&mut again, 30);
    assert!(worst < 0.03, "through the new line after the cut: {worst}");
}

/// A step down by the offset subtracted is the lead's fault going away (re-seated, repaired):
/// the subtraction ends, and the history stores that at once. Kept across restarts, the offset
/// would otherwise have read the repaired sensor 1.5 °C cold for good (the load held warm).
#[test]
fn the_offset_ends_when_the_lead_is_repaired() {
    let mut b = bench_with_a_compensated_lead();
    b.lead_c = 0.0;
    let (_, events) = reading_error(&mut b, 10);
    assert!(events.contains(&EventKind::SensorOffset), "the step down is reported: {events:?}");
    assert_eq!(b.app.carrier().sensor_offset_c(), 0.0);
    let stored = stored_history(&b);
    assert_eq!(stored.sensor_offset, crate::persist::SensorOffset::NONE);
    let (worst, _) = reading_error(&mut b, 60);
    assert!(worst < 0.05, "the reading is {worst} °C off the load");
    let mut again = restarted(&b, stored);
    let (worst, _) = reading_error(&mut again, 30);
    assert!(worst < 0.05, "after a restart: {worst} °C");
}

/// A lead repaired with the RTD unplugged (a sensor fault between) leaves no step for the watch
/// to see: the offset kept reads the repaired sensor 1.5 °C cold. `set sensor_offset_c 0`
/// clears it, the reading moves up by it at once without being taken for a step, the history
/// stores it and the record says what was cleared; only 0 is taken.
#[test]
fn set_sensor_offset_0_clears_it_after_a_repair_with_the_lead_unplugged() {
    let mut b = bench_with_a_compensated_lead();
    let load = b.load_c;
    (b.load_c, b.lead_c) = (400.0, 0.0);
    b.run(3);
    b.load_c = load;
    b.run(30);
    let (worst, _) = reading_error(&mut b, 1);
    assert!((worst - 1.5).abs() < 0.1, "the offset kept reads the repaired lead cold: {worst}");
    assert_eq!(
        b.send("set sensor_offset_c 1.5"),
        "err sensor_offset_c: usage: set sensor_offset_c 0 (only 0: it clears the offset the board measured)\r\n"
    );
    assert_eq!(b.send("set sensor_offset_c 0.00"), "ok\r\n");
    assert_eq!(b.field("sensor_offset_c"), "0.00");
    let cleared = b.saves.iter().rev().find_map(|s| match s {
        Save::Log(LogEntry::Setting { key: SettingKey::SensorOffset, value, .. }) => Some(value[0]),
        _ => None,
    });
    assert!(cleared.is_some_and(|was| (was - 1.5).abs() < 0.05), "{cleared:?}");
    let (worst, events) = reading_error(&mut b, 60);
    assert!(worst < 0.05, "the reading is {worst} °C off the load");
    assert!(!events.contains(&EventKind::SensorOffset), "{events:?}");
    assert_eq!(stored_history(&b).sensor_offset, crate::persist::SensorOffset::NONE);
    // Nothing to clear: accepted, nothing recorded.
    let logs = b.setting_logs().len();
    assert_eq!(b.send("set sensor_offset_c 0"), "ok\r\n");
    assert_eq!(b.setting_logs().len(), logs);
}

/// A heat run under way at a restart goes on from the stored history: `heat_10h` comes 10 h
/// into the run on the record's clock, as `hter monitor` raises it from the same record, and
/// the alarm's log entry gives the run's start before the restart. The board started every run
/// over at each boot: 6 h of heat, a brown-out, and the alarm came 10 h after the restart.
#[test]
fn a_heat_run_goes_on_through_a_restart() {
    let warm = |boot: &Boot| {
        let mut b = Bench::new(boot);
        (b.pinned_c, b.dither, b.load_c) = (Some(9.0), true, 9.0);
        b
    };
    let mut b = warm(&boot());
    b.run(6 * 360);
    let stored = stored_history(&b);
    // The hourly store's: 5 h of run at least (its documented layout: ms + 1, not raised).
    let run_s = (stored.runs[0] - 1) / 1000;
    assert!(stored.runs[0] >> 31 == 0 && (5 * 3600 - 20..=6 * 3600).contains(&run_s), "{run_s} s");
    let boot = Boot { history: stored, reset: ResetCause::BrownOut, log_last_s: 6 * 3600, ..boot() };
    let mut again = warm(&boot);
    let mut samples = 0u32;
    let start_s = loop {
        again.run(1);
        samples += 1;
        let raised = again.saves.iter().find_map(|s| match s {
            Save::Log(LogEntry::Alarm { kind: crate::coldchain::AlarmKind::Heat10h, start_s, .. }) => Some(*start_s),
            _ => None,
        });
        if let Some(start_s) = raised {
            break start_s;
        }
        assert!(samples < 10 * 360, "no heat_10h in 10 h after the restart");
    };
    // 10 h of run: the carried part, then the rest (to the sample).
    assert_eq!(samples, (10 * 3600 - run_s) / 10 + 1);
    // The run's start on the record's clock: the restart's record continues at the log's last
    // second, and the run before it is `run_s` long.
    assert_eq!(start_s, 6 * 3600 + 1 - run_s);
}

/// A board calibrated before it stored any settings (the firmware's `CALIBRATION` constant, or
/// an older firmware's calibration record: `Boot::calibration`): the first accepted setting of
/// any key replaced its line by the default settings' identity points (the reading moved by the
/// calibration's correction), `get` showed those points, and the settings record stored with
/// them brought identity back at every later boot.
#[test]
fn a_setting_keeps_the_calibration_the_board_booted_with() {
    use crate::units::Celsius;
    // The channel reads 0.5 °C high.
    let cal = TwoPoint::from_points(Celsius(0.5), Celsius(0.0), Celsius(25.5), Celsius(25.0)).unwrap();
    let error = |b: &mut Bench| {
        let load = b.load_c;
        b.run(1).step.raw_c.unwrap().0 - load
    };
    let mut b = Bench::new(&Boot { calibration: cal, ..boot() });
    b.lead_c = 0.5;
    b.run(10);
    assert!(error(&mut b).abs() < 0.02, "{}", error(&mut b));
    assert_eq!(b.send("set setpoint_c 4.5"), "ok\r\n");
    let after = error(&mut b);
    assert!(after.abs() < 0.02, "a setpoint change dropped the calibration: the reading is {after} °C off");
    assert_eq!(b.send("get").lines().filter(|l| l.starts_with("cal_")).count(), 2);
    let shown = line(&b);
    assert!((shown.gain - cal.gain).abs() < 1e-6 && (shown.offset_c - cal.offset_c).abs() < 1e-5, "{shown:?}");
    // The next boot from the settings it stored (the firmware then passes no calibration).
    let Some(Save::Settings(rec)) = b.saves.iter().rev().find(|s| matches!(s, Save::Settings(_))).copied() else {
        panic!("the setting is stored")
    };
    let back = SettingsRecord::decode(&rec.encode()).unwrap();
    let mut again = Bench::new(&Boot { settings: Some(back), ..boot() });
    again.lead_c = 0.5;
    again.run(10);
    let restarted = error(&mut again);
    assert!(restarted.abs() < 0.02, "the restart dropped the calibration: the reading is {restarted} °C off");
}

/// A board that booted from its stored model record runs the self-tuner resumed from it, with
/// P(0) = `RESUMED_P0`·I (0.01: the record is a model that self-tuner trusted). A commissioned
/// model starts the self-tuner with the start's P(0) (`control::adaptive`, "Resumed from a
/// stored model"), whether the board booted with a record or not; the commissioned model took
/// the boot's 0.01 instead, and adapted 100× slower than on a blank board.
#[test]
fn a_commissioned_model_starts_the_self_tuner_with_the_starts_p0_after_a_resumed_boot() {
    let mut resumed = boot();
    resumed.adaptive = Some(profile::ADAPTIVE_GPC.resumed_from(profile::START_MODEL_HTER1));
    let start_p0 = profile::ADAPTIVE_GPC.rls.p0;
    assert_ne!(resumed.adaptive.unwrap().rls.p0, start_p0);
    let mut b = Bench::new(&resumed);
    b.dither = true;
    b.run(400);
    assert_eq!(b.send("identify"), "ok\r\n");
    let mut n = 0;
    while b.field("commissioning") != "done" {
        b.run(20);
        n += 20;
        assert!(n < 3000, "commissioning={}", b.field("commissioning"));
    }
    assert_eq!(b.app.adaptive.initial.map(|m| m.k()), b.field("model_k").parse().ok());
    assert_eq!(b.app.adaptive.rls.p0, start_p0);
    // `set model` restarts the self-tuner from the model it uploads in the same way.
    let mut b = Bench::new(&resumed);
    b.run(10);
    assert_eq!(b.send("set model -1.859405,0.859802;-0.014713,-0.003021;8"), "ok\r\n");
    assert_eq!(b.app.adaptive.rls.p0, start_p0);
}

/// A service reset is refused after a fail-safe stop's own reset, not after one that an earlier
/// boot already reported and has not stored yet (a reset button pressed in that boot's first
/// minute): the stop is counted again, and the technician's reset still forgets a repair.
#[test]
fn a_stop_reported_before_does_not_refuse_a_service_reset() {
    use crate::failsafe::{panic_info, ResetRecords};
    let mut ram = ResetRecords::EMPTY;
    ram.record(&panic_info("src/step.rs", 417));
    let first = Boot { stops: ram.boot(ResetCause::Other), button_held: true, ..boot() };
    assert!(first.stops.fresh && !first.service_reset(), "the stop's own reset");
    let again = Boot { stops: ram.boot(ResetCause::Other), button_held: true, ..boot() };
    assert!(!again.stops.fresh && again.stops.latest.is_some());
    assert!(again.service_reset(), "the reset button, the stop reported before");
    let history = Recorder::new(HistoryRecord::EMPTY, 360).note_boot(ResetCause::Other, &again.stops);
    assert_eq!(history.stops_of(crate::failsafe::StopKind::Panic), 1, "still counted");
}

/// Found by fuzzing (`fuzz::the_app_starts_safe_from_arbitrary_stored_records`): a stored
/// calibration record of gain 0.9 and offset 7.5 °C (the record took offsets up to 10 °C) ran as
/// stored on a board with no settings: a load pinned at −1 °C read 6.6 °C and was cooled
/// on, the freeze guard blind to it. Refused now, the board runs the identity and its freeze
/// guard stops the cooling.
#[test]
fn a_stored_calibration_that_hides_a_freezing_load_is_not_run() {
    use crate::persist::CalibrationRecord;
    let stored = CalibrationRecord { cal: TwoPoint { gain: 0.9, offset_c: 7.5 } }.encode();
    let calibration = CalibrationRecord::decode(&stored).map_or(TwoPoint::IDENTITY, |r| r.cal);
    let mut b = Bench::new(&Boot { calibration, ..boot() });
    (b.pinned_c, b.load_c, b.dither) = (Some(-1.0), -1.0, true);
    b.run(20);
    for _ in 0..20 {
        let out = b.run(1);
        assert!(out.step.duty.get() == 0.0 || !out.step.supply_enable, "cooling a −1 °C load: {:?}", out.step);
    }
    assert_eq!(b.app.carrier().config().cal, TwoPoint::IDENTITY);
}

/// A stored record the boot refuses (here the calibration record an older firmware wrote under
/// its looser bound, the one above) is reported once: a `record_refused_calibration` event on the
/// log and the indicator latched, the refusal kept in the history. The next boots that refuse it
/// again report nothing more, and once acknowledged the indicator stays off; a boot that loads a
/// good record forgets the refusal, and a record refused after it is reported again.
#[test]
fn a_refused_record_is_reported_once_and_again_only_after_a_good_one() {
    use crate::persist::{HistoryRecord, Record};
    let refusals = |saves: &[Save]| {
        saves
            .iter()
            .filter_map(|s| match s {
                Save::Log(LogEntry::Event { kind: EventKind::RecordRefused(r), .. }) => Some(*r),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
    let history = |saves: &[Save]| {
        saves.iter().rev().find_map(|s| match s {
            Save::History(h) | Save::AlarmHistory(h) => Some(*h),
            _ => None,
        })
    };
    // A boot, 10 samples, an acknowledgement if asked: the refusals on the log, the indicator
    // at the first sample and after the acknowledgement, and the history the next boot reads.
    let run = |stored: HistoryRecord, refused: u8, ack: bool| {
        let mut b = Bench::new(&Boot { history: stored, refused, ..boot() });
        b.drain();
        let first = b.run(1).alarm;
        if ack {
            b.send("ack");
        }
        let last = b.run(10).alarm;
        (refusals(&b.saves), first, last, history(&b.saves).unwrap())
    };
    let calibration = Record::Calibration.bit();

    // (Stored behind the write gate's hold-off: a power cut before it, and the next boot, which
    // reads the history as it was, reports the refusal again.)
    let (log, first, last, h) = run(HistoryRecord::EMPTY, calibration, false);
    assert_eq!(log, [Record::Calibration]);
    assert_eq!((first, last), (Indication::Unacknowledged, Indication::Unacknowledged));
    assert_eq!(h.refused(), calibration);
    assert!(h.unacknowledged());
    // Refused again: nothing new on the log; the latch as stored, off once acknowledged.
    let (log, first, last, h) = run(h, calibration, true);
    assert_eq!((log, first, last), (vec![], Indication::Unacknowledged, Indication::Off));
    assert_eq!((h.refused(), h.unacknowledged()), (calibration, false));
    let (log, first, last, h) = run(h, calibration, false);
    assert_eq!((log, first, last), (vec![], Indication::Off, Indication::Off));
    // The history itself refused besides: it starts empty, and reports both.
    let (log, ..) = run(HistoryRecord::EMPTY, calibration | Record::History.bit(), false);
    assert_eq!(log, [Record::Calibration, Record::History]);
    // A good calibration record loads: the refusal is forgotten; refused later, it is new again.
    let (log, _, last, h) = run(h, 0, false);
    assert_eq!((log, last, h.refused()), (vec![], Indication::Off, 0));
    let (log, _, last, h) = run(h, calibration | Record::Model.bit(), false);
    assert_eq!(
        (log, last, h.refused()),
        (vec![Record::Model, Record::Calibration], Indication::Unacknowledged, calibration | Record::Model.bit())
    );
    // The build's calibration constant runs instead of the record: its refusal is no refusal.
    let constant = TwoPoint { gain: 1.013, offset_c: -0.42 };
    let mut with_constant = Boot { refused: calibration | Record::Model.bit(), ..boot() };
    with_constant.run_calibration_constant(constant);
    assert_eq!((with_constant.calibration, with_constant.refused), (constant, Record::Model.bit()));
}

/// Found by fuzzing (`fuzz::the_app_starts_safe_from_arbitrary_stored_records`): a log whose
/// newest entry is near the end of the record's clock (u32 seconds: an entry on another clock,
/// or one corrupt under a storage CRC that passed) made the next boot's entries wrap to 0 s, and
/// every boot after it again (the newest entry stays the newest): the record ran back in time
/// until the log overwrote that entry. Record time now stops at the end of its clock.
#[test]
fn record_time_does_not_wrap_at_the_end_of_its_clock() {
    for last in [u32::MAX, u32::MAX - 1, u32::MAX - 400, 7] {
        let mut b = Bench::new(&Boot { log_last_s: last, pages_lost: 1, ..boot() });
        b.run(100);
        let logged: Vec<u32> = b
            .saves
            .iter()
            .filter_map(|s| match s {
                Save::Log(e) => Some(e.t_s()),
                _ => None,
            })
            .collect();
        assert!(logged.len() >= 3, "{last}: {logged:?}");
        assert!(logged.iter().all(|&t| t > last || t == u32::MAX), "{last}: {logged:?}");
        assert!(logged.is_sorted(), "{last}: in time order: {logged:?}");
    }
}

/// Fuzzing the boot from what the flash holds (each record missing, as written, edited with its
/// CRC written again, or noise; the reset, the stops found in RAM, the pages lost, the button),
/// the records decoded as [`crate::persist::flash::restore`] decodes them: the app starts, with
/// a setpoint in its range and a law of the build, the defaults for settings that did not
/// decode, a calibration a calibration can give and that `get` shows, the build's freeze guard
/// and at most the offset the offset watch subtracts; every record it stores reads back; it
/// controls (a duty in 0 … 1) and its freeze guard stops the cooling of a load below 0 °C.
mod fuzz {
    use super::*;
    use crate::failsafe::{StopInfo, StopKind};
    use crate::persist::fuzz::{
        any_bytes, cabinet_frame, calibration_frame, edited, edits, history_frame, history_valid, model_frame,
        plausible_line, settings_frame, CABINET_FIELDS, CALIBRATION_FIELDS, HISTORY_FIELDS, MODEL_FIELDS,
        SETTINGS_FIELDS,
    };
    use crate::persist::{CabinetRecord, CalibrationRecord, ModelRecord};
    use proptest::prelude::*;
    use proptest::sample::select;

    /// What the flash and the reset hand a boot.
    #[derive(Clone, Debug)]
    struct Found {
        settings: Option<Vec<u8>>,
        calibration: Option<Vec<u8>>,
        model: Option<Vec<u8>>,
        cabinet: Option<Vec<u8>>,
        history: Option<Vec<u8>>,
        log_last_s: u32,
        reset: ResetCause,
        stops: Stops,
        pages_lost: u8,
        button_held: bool,
    }

    /// A record missing, as written, edited (its CRC written again) or noise.
    fn stored<S: Strategy<Value = Vec<u8>> + 'static>(
        frame: S,
        fields: &'static [usize],
        len: usize,
    ) -> BoxedStrategy<Option<Vec<u8>>> {
        let frame = frame.boxed();
        prop_oneof![
            1 => Just(None),
            2 => frame.clone().prop_map(Some),
            4 => (frame, edits(fields)).prop_map(|(f, e)| Some(edited(&f, &e))),
            1 => any_bytes(len).prop_map(Some),
        ]
        .boxed()
    }

    fn found() -> impl Strategy<Value = Found> {
        let stop = proptest::option::of(
            (select(StopKind::ALL.to_vec()), any::<[u32; 3]>()).prop_map(|(k, [p, a, d])| StopInfo::new(k, p, a, d)),
        );
        (
            (
                stored(settings_frame(), SETTINGS_FIELDS, SettingsRecord::LEN),
                stored(calibration_frame(), CALIBRATION_FIELDS, CalibrationRecord::LEN),
                stored(model_frame(), MODEL_FIELDS, ModelRecord::LEN),
                stored(cabinet_frame(), CABINET_FIELDS, CabinetRecord::LEN),
                stored(history_frame(), HISTORY_FIELDS, HistoryRecord::LEN),
            ),
            (
                prop_oneof![Just(0u32), any::<u32>(), (0u32..1_000).prop_map(|d| u32::MAX - d)],
                select(std::vec![ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other]),
                (stop.clone(), stop, any::<bool>()).prop_map(|(earlier, latest, fresh)| Stops {
                    earlier,
                    latest,
                    fresh,
                }),
                prop_oneof![Just(0u8), 0u8..4, any::<u8>()],
                any::<bool>(),
            ),
        )
            .prop_map(
                |(
                    (settings, calibration, model, cabinet, history),
                    (log_last_s, reset, stops, pages_lost, button_held),
                )| {
                    Found {
                        settings,
                        calibration,
                        model,
                        cabinet,
                        history,
                        log_last_s,
                        reset,
                        stops,
                        pages_lost,
                        button_held,
                    }
                },
            )
    }

    /// The boot of `f`, each record decoded and checked as the flash's restore does it: the
    /// default for one missing or refused.
    fn boot_of(f: &Found) -> Boot {
        use crate::persist::Record;
        let cfg = config().adaptive;
        let rec = |b: &Option<Vec<u8>>| b.clone().unwrap_or_default();
        let settings = SettingsRecord::decode(&rec(&f.settings));
        let calibration = CalibrationRecord::decode(&rec(&f.calibration));
        let model = ModelRecord::decode(&rec(&f.model)).and_then(|r| r.restore(&cfg));
        let cabinet = CabinetRecord::decode(&rec(&f.cabinet), &cfg);
        let history = HistoryRecord::decode(&rec(&f.history));
        // Refused: stored and failing its checks (a missing record is no refusal).
        let refused = |r: Record, b: &Option<Vec<u8>>, ok: bool| if b.is_some() && !ok { r.bit() } else { 0 };
        let refused = refused(Record::Settings, &f.settings, settings.is_ok())
            | refused(Record::Calibration, &f.calibration, calibration.is_ok())
            | refused(Record::Model, &f.model, model.is_ok())
            | refused(Record::Cabinet, &f.cabinet, cabinet.is_ok() || !cfg!(feature = "holdover"))
            | refused(Record::History, &f.history, history.is_ok());
        Boot {
            settings: settings.ok(),
            calibration: calibration.map_or(TwoPoint::IDENTITY, |r| r.cal),
            adaptive: Some(model.unwrap_or(cfg)),
            #[cfg(feature = "holdover")]
            cabinet: cabinet.ok(),
            history: history.unwrap_or(HistoryRecord::EMPTY),
            log_last_s: f.log_last_s,
            reset: f.reset,
            stops: f.stops,
            pages_lost: f.pages_lost,
            refused,
            button_held: f.button_held,
        }
    }

    /// Every record the app handed over reads back as it was handed over.
    fn saves_read_back(saves: &[Save]) -> Result<(), TestCaseError> {
        for s in saves {
            match s {
                Save::History(h) | Save::AlarmHistory(h) => {
                    history_valid(h)?;
                    prop_assert_eq!(HistoryRecord::decode(&h.encode()), Ok(*h));
                }
                Save::Settings(r) => prop_assert_eq!(SettingsRecord::decode(&r.encode()), Ok(*r)),
                Save::Model(r) => prop_assert_eq!(ModelRecord::decode(&r.encode()), Ok(*r)),
                Save::Calibration(cal) => {
                    let r = CalibrationRecord { cal: *cal };
                    prop_assert_eq!(CalibrationRecord::decode(&r.encode()), Ok(r));
                }
                #[cfg(feature = "holdover")]
                Save::Cabinet(r) => {
                    let m = CabinetRecord::decode(&r.encode(), &config().adaptive);
                    prop_assert!(m.is_ok(), "{r:?}: {m:?}");
                }
                Save::Log(e) => {
                    let again = LogEntry::decode(&e.encode()).map(|x| x.encode());
                    prop_assert_eq!(again, Ok(e.encode()), "{:?}", e);
                }
            }
        }
        Ok(())
    }

    /// Samples until a load pinned below 0 °C has its cooling off for good.
    const FREEZE_SAMPLES: usize = 40;

    fn check(f: &Found) -> Result<(), TestCaseError> {
        let boot = boot_of(f);
        let mut b = Bench::new(&boot);
        // A record refused that the stored history did not have as refused is on the log once
        // and lights the indicator; the history keeps what this boot refused. (The glue takes the
        // boot's saves before the first sample, whose own may push the oldest out.)
        b.drain();
        let first = b.run(1);
        let new = boot.newly_refused();
        let reported: Vec<crate::persist::Record> = b
            .saves
            .iter()
            .filter_map(|s| match s {
                Save::Log(LogEntry::Event { kind: EventKind::RecordRefused(r), .. }) => Some(*r),
                _ => None,
            })
            .collect();
        let want: Vec<_> = crate::persist::Record::ALL.into_iter().filter(|r| new & r.bit() != 0).collect();
        prop_assert_eq!(reported, want);
        prop_assert!(new == 0 || first.alarm.is_on(), "{first:?}");
        let stored = b.saves.iter().find_map(|s| match s {
            Save::History(h) | Save::AlarmHistory(h) => Some(*h),
            _ => None,
        });
        prop_assert_eq!(stored.map(|h| h.refused()), Some(boot.refused));
        let s = *b.app.settings();
        let (lo, hi) = crate::iface::SETPOINT_RANGE_C;
        prop_assert!((lo..=hi).contains(&s.setpoint_c), "{s:?}");
        prop_assert!(LAWS.contains(&s.law), "{s:?}");
        if boot.settings.is_none() {
            prop_assert_eq!((s.setpoint_c, s.law, s.seq), (config().setpoint_c, LAWS[0], 0), "the defaults");
        }
        // The line that runs is one a calibration gives, and the one `get` shows.
        let cal = b.app.carrier().config().cal;
        prop_assert!(plausible_line(&cal), "{cal:?}");
        let shown = s.calibration();
        prop_assert!(
            shown.is_ok_and(|c| (c.gain - cal.gain).abs() < 1e-5 && (c.offset_c - cal.offset_c).abs() < 1e-4),
            "`get` shows {s:?} ({shown:?}), {cal:?} runs"
        );
        let want = *ValidConfig::DEFAULT.get();
        prop_assert_eq!(b.app.carrier().config().supervisor, want.supervisor, "the build's guards");
        let offset = b.app.carrier().sensor_offset_c();
        prop_assert!((0.0..=want.supervisor.sensor.offset.max_comp_c).contains(&offset), "{offset}");
        b.drain();
        // `status` and `get` show whatever it restored.
        for line in ["status", "get"] {
            let reply = b.send(line);
            prop_assert!(reply.ends_with("\r\nok\r\n") && reply.is_ascii(), "{line}: {reply}");
        }
        // It controls: a duty in 0 … 1, the setpoint in force.
        b.dither = true;
        for _ in 0..20 {
            let out = b.run(1);
            prop_assert!((0.0..=1.0).contains(&out.step.duty.get()), "{out:?}");
            prop_assert_eq!(out.step.setpoint_c.0, s.setpoint_c);
        }
        // A load at −1 °C: within the calibration's 1.5 °C it reads below the freeze guard's cut,
        // and the cooling stops (the duty 0 or the supply open) and stays off.
        b.pinned_c = Some(-1.0);
        b.load_c = -1.0;
        let mut on = Vec::new();
        for k in 0..FREEZE_SAMPLES {
            let out = b.run(1);
            if out.step.duty.get() > 0.0 && out.step.supply_enable {
                on.push((k, out.step.mode, out.step.temp_c.0));
            }
        }
        prop_assert!(
            on.last().is_none_or(|&(k, _, _)| k < FREEZE_SAMPLES / 2),
            "cooling a −1 °C load: {on:?} ({cal:?}, offset {offset})"
        );
        saves_read_back(&b.saves)?;
        // The record's time goes on from the log's newest entry: never back before it.
        for s in &b.saves {
            if let Save::Log(e) = s {
                prop_assert!(e.t_s() >= boot.log_last_s, "{e:?} after a log up to {} s", boot.log_last_s);
            }
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]
        #[test]
        fn the_app_starts_safe_from_arbitrary_stored_records(f in found()) {
            check(&f)?;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]
        #[test]
        #[ignore = "many cases: CI runs it in release with `-- --ignored`"]
        fn the_app_starts_safe_from_arbitrary_stored_records_long(f in found()) {
            check(&f)?;
        }
    }
}
