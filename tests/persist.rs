//! `persist::flash::Store` over a mock NOR flash that behaves like the STM32L4's: 64-bit double
//! words with ECC, programmed once after an erase (or over with all zeros, which RM0351 allows),
//! bits only 1 → 0, erase sets a page to 0xFF. It can lose power after any number of word
//! programs or page erases. With [`Tear::Ecc`] (the L4) a cut program leaves its double word
//! half programmed and failing its ECC check, and a cut erase leaves every word of the page that
//! held data failing it: the erase acts on the whole page at once, so each programmed cell is
//! left somewhere between its levels, and RM0351 only promises an undefined page (a word that
//! happens to read back with a consistent ECC is the other mode's case). A read covering such a
//! word fails with its address, as the L4's ECCD NMI, noted by the firmware's handler, makes the
//! flash reader fail. With [`Tear::Readable`] the torn word or page reads back half written
//! (flash without ECC, or a tear the ECC happens to miss). After every cut point of a sequence
//! of stores the board "reboots" (a fresh `Store` over the same bytes), loads every record as
//! the firmware's boot does, and must read, for every key, the last completed record or the one
//! being written — never a corrupt one, never an error — leaving no ECC damage behind.

use embassy_futures::block_on;
use hter::calib::TwoPoint;
use hter::control::adaptive::{AdaptiveConfig, SelfTuning};
use hter::persist::flash::{LoadStatus, Repairs, Store, StoreError, MAX_REPAIRS};
use hter::persist::{DecodeError, HistoryRecord, ModelRecord, ResetCause};
use hter::profile::{ADAPTIVE_GPC, START_MODEL_HTER1, START_MODEL_HTER2};

use hal_sim::flash::{CutIn, MockEcc, MockFlash, Tear};

type MockStore<const PAGE: usize> = Store<MockFlash<PAGE>, MockEcc>;

fn gpc() -> AdaptiveConfig {
    ADAPTIVE_GPC
}

fn open<const PAGE: usize>(flash: MockFlash<PAGE>, pages: usize) -> MockStore<PAGE> {
    let ecc = flash.ecc.clone();
    Store::new(flash, ecc, 0..(pages * PAGE) as u32).expect("page-aligned region of ≥ 2 pages")
}

/// Power off and on again: a fresh store (nothing cached) over the same bytes.
fn reboot<const PAGE: usize>(store: MockStore<PAGE>, pages: usize) -> MockStore<PAGE> {
    let mut flash = store.release();
    flash.power_on();
    open(flash, pages)
}

#[test]
fn blank_flash_gives_defaults_and_says_missing() {
    let mut store = open(MockFlash::<2048>::blank(4), 4);
    block_on(async {
        let cfg = store.load_adaptive(&gpc()).await;
        assert_eq!(cfg.status, LoadStatus::Missing);
        assert_eq!(cfg.value, gpc());
        let cal = store.load_calibration().await;
        assert_eq!((cal.value, cal.status), (TwoPoint::IDENTITY, LoadStatus::Missing));
        let hist = store.load_history().await;
        assert_eq!((hist.value, hist.status), (HistoryRecord::EMPTY, LoadStatus::Missing));
    });
}

#[test]
fn region_must_be_two_aligned_pages() {
    assert_eq!(Store::new(MockFlash::<2048>::blank(4), MockEcc::default(), 0..2048).err(), Some(StoreError::Config));
    assert_eq!(Store::new(MockFlash::<2048>::blank(4), MockEcc::default(), 8..4104).err(), Some(StoreError::Config));
}

#[test]
fn records_survive_a_reboot_and_restart_the_self_tuner() {
    let mut store = open(MockFlash::<2048>::blank(4), 4);
    let model = ModelRecord::from_model(&START_MODEL_HTER2).unwrap();
    let cal = TwoPoint { gain: 1.013, offset_c: -0.42 };
    let mut hist = HistoryRecord::EMPTY;
    hist.note_reset(ResetCause::Watchdog);
    hist.min_c = Some(1.5);
    hist.max_c = Some(9.0);
    block_on(async {
        store.save_model(&model).await.unwrap();
        store.save_calibration(cal).await.unwrap();
        store.save_history(&hist).await.unwrap();
    });
    let mut store = reboot(store, 4);
    block_on(async {
        let cfg = store.load_adaptive(&gpc()).await;
        assert_eq!(cfg.status, LoadStatus::Restored);
        assert_eq!(cfg.value.k, 6);
        let tuner = SelfTuning::new(cfg.value, 10.0, 0.5).expect("a restored configuration is valid");
        let trusted = tuner.trusted_model().expect("a plausible restored model is trusted at once");
        assert_eq!(ModelRecord::from_model(&trusted), Some(model));
        // The self-tuner's θ = [a1 a2 b0 … b3 d]: the record's six, b2 = b3 = 0 for this
        // second-order start model.
        assert_eq!(tuner.theta()[..6], model.theta);
        assert_eq!(store.load_calibration().await.value, cal);
        let h = store.load_history().await;
        assert_eq!((h.value, h.status), (hist, LoadStatus::Restored));
    });
}

#[test]
fn implausible_or_out_of_range_records_give_defaults() {
    let mut store = open(MockFlash::<2048>::blank(4), 4);
    block_on(async {
        // CRC-correct and finite, but A has a pole at 1.2.
        let unstable = ModelRecord { theta: [-2.2, 1.2, -0.03, -0.03, 0.0, 0.0], k: 5 };
        store.save_model(&unstable).await.unwrap();
        store.save_calibration(TwoPoint { gain: 1.5, offset_c: 0.0 }).await.unwrap();
    });
    let mut store = reboot(store, 4);
    block_on(async {
        assert_eq!(
            store.load_model_record().await,
            Ok(ModelRecord { theta: [-2.2, 1.2, -0.03, -0.03, 0.0, 0.0], k: 5 })
        );
        let cfg = store.load_adaptive(&gpc()).await;
        assert_eq!(cfg.status, LoadStatus::Invalid(DecodeError::Implausible));
        assert_eq!(cfg.value, gpc());
        let cal = store.load_calibration().await;
        assert_eq!((cal.value, cal.status), (TwoPoint::IDENTITY, LoadStatus::Invalid(DecodeError::OutOfRange)));
    });
}

/// xorshift32, for reproducible garbage.
fn noise(seed: u32, n: usize) -> Vec<u8> {
    let mut x = seed;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect()
}

#[test]
fn garbage_flash_gives_defaults_and_can_be_reclaimed() {
    for seed in 1..=20u32 {
        let mut flash = MockFlash::<2048>::blank(4);
        flash.bytes = noise(seed, 4 * 2048);
        let mut store = open(flash, 4);
        block_on(async {
            let cfg = store.load_adaptive(&gpc()).await;
            assert_ne!(cfg.status, LoadStatus::Restored, "seed {seed}");
            assert_eq!(cfg.value, gpc());
            let cal = store.load_calibration().await;
            assert_ne!(cal.status, LoadStatus::Restored);
            assert_eq!(cal.value, TwoPoint::IDENTITY);
            let hist = store.load_history().await;
            assert_ne!(hist.status, LoadStatus::Restored);
            assert_eq!(hist.value, HistoryRecord::EMPTY);
            // What the firmware does when a save fails on a corrupt region: erase, then save.
            let rec = ModelRecord::from_model(&START_MODEL_HTER1).unwrap();
            if store.save_model(&rec).await.is_err() {
                store.erase_all().await.unwrap();
                store.save_model(&rec).await.unwrap();
            }
            assert_eq!(store.load_model_record().await, Ok(rec));
        });
    }
}

/// One step of the store sequence.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Save {
    Model(ModelRecord),
    Cal(TwoPoint),
    History(HistoryRecord),
}

impl Save {
    fn slot(&self) -> usize {
        match self {
            Save::Model(_) => 0,
            Save::Cal(_) => 1,
            Save::History(_) => 2,
        }
    }
}

/// Model every step, calibration every 5th, history every 3rd: enough items to fill the region
/// several times, so cuts also land in page erases and in the copying of live items.
fn sequence(n: usize) -> Vec<Save> {
    let mut out = Vec::new();
    for i in 0..n {
        let f = i as f32;
        out.push(Save::Model(ModelRecord { theta: [-1.75 + 0.001 * f, 0.75, -0.027, -0.03, -0.01, -0.005], k: 5 }));
        if i % 5 == 0 {
            out.push(Save::Cal(TwoPoint { gain: 1.0 + 0.0005 * f, offset_c: -0.01 * f }));
        }
        if i % 3 == 0 {
            let mut h = HistoryRecord::EMPTY;
            h.below_2_s = 60 * i as u32;
            h.resets[2] = i as u16;
            out.push(Save::History(h));
        }
    }
    out
}

async fn apply<const PAGE: usize>(store: &mut MockStore<PAGE>, s: &Save) -> Result<(), StoreError> {
    match s {
        Save::Model(m) => store.save_model(m).await,
        Save::Cal(c) => store.save_calibration(*c).await,
        Save::History(h) => store.save_history(h).await,
    }
}

/// What each key reads back after a reboot.
async fn read_back<const PAGE: usize>(store: &mut MockStore<PAGE>) -> [Result<Option<Save>, LoadStatus>; 3] {
    let model = match store.load_model_record().await {
        Ok(m) => Ok(Some(Save::Model(m))),
        Err(LoadStatus::Missing) => Ok(None),
        Err(e) => Err(e),
    };
    let found = |status: LoadStatus, s: Save| match status {
        LoadStatus::Restored => Ok(Some(s)),
        LoadStatus::Missing => Ok(None),
        e => Err(e),
    };
    let cal = store.load_calibration().await;
    let hist = store.load_history().await;
    [model, found(cal.status, Save::Cal(cal.value)), found(hist.status, Save::History(hist.value))]
}

/// What a reboot after a cut read for the key that was being written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outcome {
    /// The cut fell after the sequence.
    NoCut,
    /// The previous record (the torn one was discarded).
    Old,
    /// The record being written.
    New,
}

/// One cut and the boot after it.
#[derive(Clone, Copy, Debug)]
struct CutResult {
    outcome: Outcome,
    cut_in: Option<CutIn>,
    /// Words failing their ECC check the cut left.
    torn: usize,
    /// What the boot repaired.
    repairs: Repairs,
}

/// The boot's loads, as `firmware/src/persist.rs::restore` makes them, then the checks: every
/// key reads its last committed record or (for the key in flight) the new one, and no ECC damage
/// is left. Returns the outcome for the key in flight and what the boot repaired.
fn boot_and_check<const PAGE: usize>(
    store: MockStore<PAGE>,
    pages: usize,
    committed: &[Option<Save>; 3],
    in_flight: Option<Save>,
    what: &str,
) -> (MockStore<PAGE>, Outcome, Repairs) {
    let mut store = reboot(store, pages);
    let got = block_on(async {
        store.scrub().await.unwrap_or_else(|e| panic!("{what}: scrub: {e:?}"));
        read_back(&mut store).await
    });
    let repairs = store.repairs();
    assert!(repairs.total() as usize <= 3 * MAX_REPAIRS, "{what}: {repairs:?}: the repairs are bounded");
    let outcome = match in_flight {
        None => Outcome::NoCut,
        Some(s) if got[s.slot()] == Ok(Some(s)) => Outcome::New,
        Some(_) => Outcome::Old,
    };
    for (slot, got) in got.iter().enumerate() {
        let got = got.unwrap_or_else(|e| panic!("{what}, key {slot}: {e:?} instead of a record"));
        let new = in_flight.filter(|s| s.slot() == slot);
        assert!(
            got == committed[slot] || (new.is_some() && got == new),
            "{what}, key {slot}: read {got:?}, expected {:?} or {new:?}",
            committed[slot]
        );
    }
    let flash = store.release();
    assert_eq!(flash.torn_words(), 0, "{what}: the boot left ECC damage ({repairs:?})");
    (open(flash, pages), outcome, repairs)
}

/// Runs `seq` with power lost at operation `cut`, reboots, and checks every key; then checks
/// that the rebooted store keeps working.
fn cut_and_check<const PAGE: usize>(seq: &[Save], pages: usize, cut: usize, tear: Tear) -> CutResult {
    let mut flash = MockFlash::<PAGE>::with_tear(pages, tear);
    flash.ops_left = Some(cut);
    let mut store = open(flash, pages);
    let mut committed: [Option<Save>; 3] = [None; 3];
    let mut in_flight = None;
    block_on(async {
        for s in seq {
            match apply(&mut store, s).await {
                Ok(()) => committed[s.slot()] = Some(*s),
                Err(e) => {
                    assert_eq!(e, StoreError::Flash, "cut {cut}: only the power loss may fail a store");
                    in_flight = Some(*s);
                    break;
                }
            }
        }
    });
    let flash = store.release();
    let (cut_in, torn) = (flash.cut_in, flash.torn_words());
    let what = format!("{tear:?} cut {cut} in {cut_in:?}");
    let (mut store, outcome, repairs) = boot_and_check(open(flash, pages), pages, &committed, in_flight, &what);
    block_on(async {
        let next = Save::Model(ModelRecord { theta: [-1.6, 0.65, -0.02, -0.02, -0.01, 0.0], k: 4 });
        apply(&mut store, &next).await.unwrap_or_else(|e| panic!("{what}: store after reboot: {e:?}"));
        assert_eq!(read_back(&mut store).await[0], Ok(Some(next)), "{what}");
    });
    CutResult { outcome, cut_in, torn, repairs }
}

/// The operation count of the uncut sequence, how many page erases it needed, and the
/// operation count at the end of each store (the store is reopened between stores to read it,
/// which the uncached map does not notice).
fn count_ops<const PAGE: usize>(seq: &[Save], pages: usize) -> (usize, usize, Vec<usize>) {
    let mut flash = MockFlash::<PAGE>::blank(pages);
    let mut ends = Vec::new();
    for s in seq {
        let mut store = open(flash, pages);
        block_on(apply(&mut store, s)).unwrap();
        flash = store.release();
        ends.push(flash.ops);
    }
    assert_eq!(flash.rewrites, 0, "the store programmed a word twice");
    (flash.ops, flash.erases, ends)
}

/// Cuts power at every operation of `seq` in `tear` mode and checks each boot; prints and
/// returns the tally.
fn sweep<const PAGE: usize>(seq: &[Save], pages: usize, tear: Tear, step: usize) -> Vec<CutResult> {
    let (ops, erases, ends) = count_ops::<PAGE>(seq, pages);
    assert!(erases >= 1, "the sequence must exercise page erases (got {erases})");
    let results: Vec<CutResult> =
        (0..ops).step_by(step).map(|cut| cut_and_check::<PAGE>(seq, pages, cut, tear)).collect();
    // sequential-storage writes an item's header, then its data: a cut anywhere before a
    // store's last operation leaves the previous record; only a cut in that last word can find
    // the new item already readable (its data complete: the record's own CRC-32 checked it, and
    // `boot_and_check` compared it whole). Seen in the readable mode, whose torn word keeps its
    // first half: the history record's last word holds only padding there.
    for (i, r) in results.iter().enumerate() {
        let cut = i * step;
        assert_ne!(r.outcome, Outcome::NoCut, "cut {cut} did not interrupt a store");
        if r.outcome == Outcome::New {
            assert!(
                ends.contains(&(cut + 1)),
                "{tear:?} cut {cut} exposed the new record before its store's last operation"
            );
        }
        if tear == Tear::Ecc {
            // A cut program always tears its word; every tear is found and repaired at boot.
            if r.cut_in == Some(CutIn::Program) {
                assert_eq!(r.torn, 1, "cut {cut}");
            }
            assert_eq!(r.torn > 0, r.repairs.total() > 0, "cut {cut}: {r:?}");
        }
    }
    assert_eq!(cut_and_check::<PAGE>(seq, pages, ops, tear).outcome, Outcome::NoCut, "one past the end");
    for kind in [CutIn::Program, CutIn::Erase] {
        let of: Vec<&CutResult> = results.iter().filter(|r| r.cut_in == Some(kind)).collect();
        let count = |o| of.iter().filter(|r| r.outcome == o).count();
        let sum = |f: fn(&Repairs) -> u16| of.iter().map(|r| usize::from(f(&r.repairs))).sum::<usize>();
        println!(
            "{tear:?}, {PAGE}-byte pages: {} cuts in {kind:?} of {ops} ops: boot read the old record {}, the new {}; \
             words cleared {}, pages erased {}",
            of.len(),
            count(Outcome::Old),
            count(Outcome::New),
            sum(|r| r.words_cleared),
            sum(|r| r.pages_erased)
        );
    }
    results
}

#[test]
fn power_loss_at_every_operation_small_pages() {
    // 4 pages of 512 bytes: the region wraps several times within the sequence.
    let seq = sequence(60);
    for tear in [Tear::Ecc, Tear::Readable] {
        let results = sweep::<512>(&seq, 4, tear, 1);
        let old = results.iter().filter(|r| r.outcome == Outcome::Old).count();
        assert!(
            old > results.len() * 9 / 10,
            "{tear:?}: only {old} of {} cuts kept the previous record",
            results.len()
        );
        let erase_cuts = results.iter().filter(|r| r.cut_in == Some(CutIn::Erase)).count();
        assert!(erase_cuts >= 4, "{tear:?}: the sweep must cut page erases (got {erase_cuts})");
        if tear == Tear::Ecc {
            let erased: u16 = results.iter().map(|r| r.repairs.pages_erased).sum();
            let cleared: u16 = results.iter().map(|r| r.repairs.words_cleared).sum();
            assert!(erased > 0 && cleared > 0, "both repairs must be exercised ({erased} erased, {cleared} cleared)");
        }
    }
}

#[test]
fn power_loss_with_stm32l4_pages() {
    // The firmware's geometry: 4 pages × 2 KiB. Every 3rd cut point keeps the run short.
    let seq = sequence(120);
    sweep::<2048>(&seq, 4, Tear::Ecc, 3);
}

/// A second cut during the boot after the first (in its repair, or in the store that follows):
/// the boot after that still reads committed records only and leaves no ECC damage.
#[test]
fn power_loss_during_the_repair_after_a_power_loss() {
    let seq = sequence(40);
    let (ops, _, _) = count_ops::<512>(&seq, 4);
    let mut second_cuts = 0;
    for cut in 0..ops {
        let mut flash = MockFlash::<512>::blank(4);
        flash.ops_left = Some(cut);
        let mut store = open(flash, 4);
        let mut committed: [Option<Save>; 3] = [None; 3];
        let mut in_flight = None;
        block_on(async {
            for s in &seq {
                match apply(&mut store, s).await {
                    Ok(()) => committed[s.slot()] = Some(*s),
                    Err(_) => {
                        in_flight = Some(*s);
                        break;
                    }
                }
            }
        });
        let before = store.release();
        if before.torn_words() == 0 {
            continue;
        }
        // The operations of the boot's repairs and of the next store, then each one cut.
        let next = Save::Cal(TwoPoint { gain: 0.99, offset_c: 0.2 });
        let boot_ops = |flash: MockFlash<512>, cut2: Option<usize>| {
            let mut flash = flash;
            flash.power_on();
            flash.ops_left = cut2;
            let start = flash.ops;
            let mut store = open(flash, 4);
            let stored = block_on(async {
                let _ = store.scrub().await;
                let _ = read_back(&mut store).await;
                apply(&mut store, &next).await.is_ok()
            });
            let flash = store.release();
            (flash.ops - start, stored, flash)
        };
        let clone = |f: &MockFlash<512>| {
            let mut c = MockFlash::<512>::blank(4);
            c.bytes = f.bytes.clone();
            c.torn = f.torn.clone();
            c
        };
        let (n, _, _) = boot_ops(clone(&before), None);
        for cut2 in 0..n {
            let (_, stored, flash) = boot_ops(clone(&before), Some(cut2));
            assert!(!stored, "cut {cut}/{cut2}: the cut must fail the store");
            // The in-flight record may have surfaced at the first boot; `next` may be complete.
            let what = format!("cut {cut} then {cut2}");
            let store = open(flash, 4);
            let mut s = reboot(store, 4);
            let got = block_on(async {
                s.scrub().await.unwrap_or_else(|e| panic!("{what}: scrub: {e:?}"));
                read_back(&mut s).await
            });
            let flash = s.release();
            assert_eq!(flash.torn_words(), 0, "{what}: ECC damage left");
            for (slot, got) in got.iter().enumerate() {
                let got = got.unwrap_or_else(|e| panic!("{what}, key {slot}: {e:?}"));
                let allowed =
                    [committed[slot], in_flight.filter(|s| s.slot() == slot), Some(next).filter(|s| s.slot() == slot)];
                assert!(allowed.contains(&got), "{what}, key {slot}: read {got:?}, allowed {allowed:?}");
            }
            second_cuts += 1;
        }
    }
    println!("{ops} first cuts, {second_cuts} second cuts during the boot after them");
    assert!(second_cuts > ops / 2, "{second_cuts} second cuts");
}

/// Wear of the firmware's use: model saves only, 4 pages × 2 KiB. The README and
/// `firmware/src/config.rs` quote this figure: ≥ 50 saves per page erase, and the pages are
/// erased in turn, so each page once per ≥ 200 saves. (Measured: 2000 saves, 37 erases; the
/// first three pages fill before the first erase. A v2 model record of 31 bytes is a 40-byte
/// item, 8 header and 1 + 31 in 8-byte words; the 23-byte v1 record's was 32 and gave ≥ 60.)
#[test]
fn wear_per_save() {
    let mut store = open(MockFlash::<2048>::blank(4), 4);
    let saves = 2000;
    block_on(async {
        for i in 0..saves {
            let rec = ModelRecord { theta: [-1.75 + 1e-5 * i as f32, 0.75, -0.027, -0.03, -0.01, -0.005], k: 5 };
            store.save_model(&rec).await.unwrap();
        }
    });
    let erases = store.release().erases;
    println!("{saves} model saves: {erases} page erases, {:.1} saves per erase", saves as f32 / erases as f32);
    assert!(erases > 0);
    assert!(saves / erases >= 50, "{erases} erases for {saves} saves");
}

/// The board's cadence (`hter::profile`): the history every `HISTORY_SAVE_S` (an hour), the
/// model every `MODEL_SAVE_S` (4 h) of trusted learning and a boot's first after 1 h, plus the
/// history each boot stores once its write gate opens (`BOOTS_PER_DAY`, a pessimistic field
/// use: a carrier unplugged and replugged every hour, each boot storing its model too), and the
/// history every 10 minutes while the load is outside 2…8 °C (`persist::EXCURSION_SAVES`: a
/// carrier that never gets back into range). Prints and checks how long the four pages last at
/// the L4's 10 000 erase cycles (datasheet DS10198, "NEND") in each case.
#[test]
fn wear_at_the_firmware_cadence() {
    use hter::control::AdaptiveMode;
    use hter::persist::ModelCadence;
    use hter::profile::{HISTORY_SAVE_S, MODEL_SAVE_S};
    const BOOTS_PER_DAY: u32 = 24;
    let days = 60;
    // The board's own `ModelCadence`, pushed once an hour with every hour trusted (the most
    // stores): a boot's first model after a quarter of MODEL_SAVE_S, then every MODEL_SAVE_S.
    let learner = hter::profile::controller(hter::profile::Kind::Gpc, 10.0, 0.4).unwrap();
    let cadence = || ModelCadence::new(MODEL_SAVE_S / HISTORY_SAVE_S);
    let years = |boots_per_day: u32, history_every_s: u32| {
        let mut store = open(MockFlash::<2048>::blank(4), 4);
        let boot_every_s = 86_400 / boots_per_day.max(1);
        block_on(async {
            let mut models = cadence();
            for n in 0..days * 86_400 / history_every_s {
                let t_s = n * history_every_s;
                let mut h = HistoryRecord::EMPTY;
                (h.recorded_s, h.excursions) = (t_s, t_s / (7 * 3600));
                if boots_per_day > 0 && t_s.is_multiple_of(boot_every_s) {
                    let mut boot = h;
                    boot.note_reset(ResetCause::BrownOut);
                    store.save_history(&boot).await.unwrap();
                    models = cadence();
                }
                store.save_history(&h).await.unwrap();
                let hourly = t_s.is_multiple_of(HISTORY_SAVE_S);
                if hourly && models.push(Some(AdaptiveMode::Adaptive), &learner).is_some() {
                    // A record that differs at every store, as a learning estimate's does.
                    let rec =
                        ModelRecord { theta: [-1.75 + 1e-5 * n as f32, 0.75, -0.027, -0.03, -0.01, -0.005], k: 5 };
                    store.save_model(&rec).await.unwrap();
                }
            }
        });
        let erases = store.release().erases;
        assert!(erases > 0);
        let days_per_page_erase = (days * 4) as f64 / erases as f64;
        let years = 10_000.0 * days_per_page_erase / 365.25;
        println!(
            "{days} days, {boots_per_day} boots a day, the history every {history_every_s} s: {erases} page \
             erases, each page erased every {days_per_page_erase:.1} days: {years:.0} years to 10 000 cycles"
        );
        years
    };
    let quiet = years(0, HISTORY_SAVE_S);
    let booting = years(BOOTS_PER_DAY, HISTORY_SAVE_S);
    let excursion = years(0, HISTORY_SAVE_S / hter::persist::EXCURSION_SAVES);
    assert!(quiet >= 50.0, "{quiet:.0} years");
    assert!(booting >= 25.0 && booting < quiet, "{booting:.0} years with {BOOTS_PER_DAY} boots a day");
    assert!(excursion >= 8.0 && excursion < quiet, "{excursion:.0} years out of range");
}

// ---- The settings record and the cold-chain log (issue 16) ----

use hter::iface::Law;
use hter::persist::flash::LogStore;
use hter::persist::log::{Interval, LogEntry};
use hter::persist::SettingsRecord;
use hter::step::Mode;

const L4_PAGE: usize = 2048;

fn settings(seq: u32, setpoint_c: f32, law: Law) -> SettingsRecord {
    SettingsRecord { seq, setpoint_c, law, cal_ice: [0.1, 0.0], cal_warm: [25.2, 25.0] }
}

#[test]
fn a_power_cut_anywhere_in_a_settings_write_leaves_the_old_or_the_new_settings() {
    let (old, new) = (settings(1, 4.0, Law::Gpc), settings(2, 5.0, Law::Pi));
    // Fill the region's pages with history first, so the cut also falls in page turns.
    let mut store = open(MockFlash::<L4_PAGE>::blank(4), 4);
    let mut h = HistoryRecord::EMPTY;
    h.recorded_s = 1;
    for _ in 0..30 {
        block_on(store.save_history(&h)).unwrap();
    }
    block_on(store.save_settings(&old)).unwrap();
    let image = store.release().bytes;
    let ops = {
        let mut f = MockFlash::<L4_PAGE>::blank(4);
        f.bytes = image.clone();
        let mut s = open(f, 4);
        block_on(s.save_settings(&new)).unwrap();
        s.release().ops
    };
    let (mut saw_old, mut saw_new) = (0, 0);
    for cut in 0..=ops {
        let mut f = MockFlash::<L4_PAGE>::blank(4);
        f.bytes = image.clone();
        f.cut_after(cut);
        let mut s = open(f, 4);
        let written = block_on(s.save_settings(&new)).is_ok();
        let mut s = reboot(s, 4);
        block_on(s.scrub()).unwrap();
        match block_on(s.load_settings()) {
            Ok(r) if r == new => saw_new += 1,
            Ok(r) if r == old => {
                assert!(!written, "cut {cut}: a completed write must be read back");
                saw_old += 1
            }
            other => panic!("cut {cut}: {other:?}"),
        }
        assert_eq!(block_on(s.load_history()).value.recorded_s, 1, "cut {cut}: the history survives");
        assert_eq!(s.release().torn_words(), 0, "cut {cut}: no ECC damage left behind");
    }
    assert!(saw_old > 0 && saw_new > 0, "the sweep covers both outcomes: {saw_old} / {saw_new}");
}

/// The cabinet model (the holdover's, its own record, issue 16): H-TER I's monotone model with
/// b1 > 0, which the self-tuner's model record would refuse.
fn cabinet(a1: f32, b1: f32) -> hter::model::Model {
    hter::model::Model::second_order([a1, 0.939_181], [-0.279_814, b1], 9).unwrap()
}

#[test]
fn a_power_cut_anywhere_in_a_cabinet_model_write_leaves_the_old_or_the_new_one() {
    use hter::persist::CabinetRecord;
    let (old, new) = (cabinet(-1.938_996, 0.271_719), cabinet(-1.938_5, 0.271_2));
    let rec = |m| CabinetRecord::from_model(&m).unwrap();
    let model = ModelRecord::from_model(&START_MODEL_HTER1).unwrap();
    let mut store = open(MockFlash::<L4_PAGE>::blank(4), 4);
    let mut h = HistoryRecord::EMPTY;
    h.recorded_s = 1;
    for _ in 0..30 {
        block_on(store.save_history(&h)).unwrap();
        // The self-tuner's periodic save has its own key: it never replaces the cabinet model.
        block_on(store.save_model(&model)).unwrap();
    }
    block_on(store.save_cabinet(&rec(old))).unwrap();
    block_on(store.save_model(&model)).unwrap();
    let image = store.release().bytes;
    let ops = {
        let mut f = MockFlash::<L4_PAGE>::blank(4);
        f.bytes = image.clone();
        let mut s = open(f, 4);
        assert_eq!(block_on(s.load_cabinet(&gpc())), Ok(old), "the model save left the cabinet model");
        block_on(s.save_cabinet(&rec(new))).unwrap();
        s.release().ops
    };
    let (mut saw_old, mut saw_new) = (0, 0);
    for tear in [Tear::Ecc, Tear::Readable] {
        for cut in 0..=ops {
            let mut f = MockFlash::<L4_PAGE>::blank(4);
            f.bytes = image.clone();
            f.tear = tear;
            f.cut_after(cut);
            let mut s = open(f, 4);
            let written = block_on(s.save_cabinet(&rec(new))).is_ok();
            let mut s = reboot(s, 4);
            block_on(s.scrub()).unwrap();
            match block_on(s.load_cabinet(&gpc())) {
                Ok(m) if m == new => saw_new += 1,
                Ok(m) if m == old => {
                    assert!(!written, "{tear:?} cut {cut}: a completed write must be read back");
                    saw_old += 1
                }
                other => panic!("{tear:?} cut {cut}: {other:?}"),
            }
            assert_eq!(block_on(s.load_model_record()), Ok(model), "{tear:?} cut {cut}: the model record survives");
            assert_eq!(block_on(s.load_history()).value.recorded_s, 1, "{tear:?} cut {cut}: the history survives");
            assert_eq!(s.release().torn_words(), 0, "{tear:?} cut {cut}: no ECC damage left behind");
        }
    }
    assert!(saw_old > 0 && saw_new > 0, "the sweep covers both outcomes: {saw_old} / {saw_new}");
}

#[test]
fn a_stored_cabinet_model_is_checked_on_restore_as_an_upload_is() {
    use hter::persist::CabinetRecord;
    let mut store = open(MockFlash::<L4_PAGE>::blank(4), 4);
    assert_eq!(block_on(store.load_cabinet(&gpc())), Err(LoadStatus::Missing));
    // The slow lag heats (b0·p1 + b1 > 0): refused as `set model` refuses it.
    let heating = CabinetRecord { theta: [-1.94, 0.9401, -0.02, 0.0201], k: 9 };
    block_on(store.save_cabinet(&heating)).unwrap();
    assert_eq!(block_on(store.load_cabinet(&gpc())), Err(LoadStatus::Invalid(DecodeError::Implausible)));
    let good = cabinet(-1.938_996, 0.271_719);
    block_on(store.save_cabinet(&CabinetRecord::from_model(&good).unwrap())).unwrap();
    let mut store = reboot(store, 4);
    let restored = block_on(hter::persist::flash::restore_records(&mut store, Some(&gpc())));
    assert_eq!(restored.cabinet, Err(LoadStatus::Missing), "the build without the interface keeps none");
    assert_eq!(block_on(store.load_cabinet(&gpc())), Ok(good));
}

fn entry(i: u32) -> LogEntry {
    let c = 4.0 + (i % 50) as f32 * 0.01;
    LogEntry::Interval {
        t_s: 300 * (i + 1),
        interval: Interval { mean_c: c, min_c: c - 0.1, max_c: c + 0.1, duty: 0.45, mode: Mode::Normal },
    }
}

fn log_entries<const PAGE: usize>(log: &mut LogStore<MockFlash<PAGE>, MockEcc>) -> Vec<LogEntry> {
    let mut out = Vec::new();
    let skipped = block_on(log.for_each(0, async |e: &LogEntry| {
        out.push(*e);
        true
    }))
    .unwrap();
    assert_eq!(skipped, 0);
    out
}

fn open_log<const PAGE: usize>(flash: MockFlash<PAGE>, pages: usize) -> LogStore<MockFlash<PAGE>, MockEcc> {
    let ecc = flash.ecc.clone();
    LogStore::new(flash, ecc, 0..(pages * PAGE) as u32).unwrap()
}

#[test]
fn the_log_keeps_thirty_days_of_intervals_in_its_region_and_overwrites_the_oldest_after() {
    // The firmware's log region: 248 pages of 2 KiB.
    let mut log = open_log(MockFlash::<L4_PAGE>::blank(248), 248);
    let days = 30 * 288;
    for i in 0..days {
        block_on(log.push(&entry(i))).unwrap();
    }
    let kept = log_entries(&mut log);
    assert_eq!(kept.len(), days as usize, "30 days of 5-minute intervals fit");
    assert_eq!(kept.first(), Some(&entry(0)));
    assert_eq!(block_on(log.last_t_s()), Ok(300 * days));
    // Another 30 days: the oldest go, the newest stay, in order.
    for i in days..2 * days {
        block_on(log.push(&entry(i))).unwrap();
    }
    let kept = log_entries(&mut log);
    assert!(kept.len() >= days as usize, "at least 30 days kept: {}", kept.len());
    assert_eq!(kept.last(), Some(&entry(2 * days - 1)));
    assert!(kept.windows(2).all(|w| w[0].t_s() < w[1].t_s()));
}

#[test]
fn a_power_cut_anywhere_in_a_log_append_loses_at_most_the_entry_being_written() {
    let pages = 4;
    let mut base = open_log(MockFlash::<L4_PAGE>::blank(pages), pages);
    // Nearly full: the appends below turn pages and overwrite the oldest.
    let n0 = 4 * 63 - 3;
    for i in 0..n0 {
        block_on(base.push(&entry(i))).unwrap();
    }
    let image = base.release().bytes;
    for cut in 0..60 {
        let mut f = MockFlash::<L4_PAGE>::blank(pages);
        f.bytes = image.clone();
        f.cut_after(cut);
        let mut log = open_log(f, pages);
        let mut done = n0;
        for i in n0..n0 + 8 {
            if block_on(log.push(&entry(i))).is_err() {
                break;
            }
            done = i + 1;
        }
        let mut flash = log.release();
        flash.power_on();
        let mut log = open_log(flash, pages);
        block_on(log.scrub()).unwrap();
        let kept = log_entries(&mut log);
        let newest = kept.last().map(|e| e.t_s() / 300 - 1).unwrap();
        assert!(newest + 1 == done || newest == done, "cut {cut}: newest {newest}, {done} completed");
        assert!(kept.windows(2).all(|w| w[0].t_s() < w[1].t_s()), "cut {cut}: in order");
        // Every completed entry that the overwrite did not reclaim is there.
        let oldest = kept.first().unwrap().t_s() / 300 - 1;
        assert_eq!(kept.len() as u32, newest - oldest + 1, "cut {cut}: no hole");
        // And the log takes appends again.
        block_on(log.push(&entry(1000))).unwrap();
        assert_eq!(log.release().torn_words(), 0);
    }
}
