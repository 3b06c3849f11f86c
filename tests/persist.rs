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

/// What a boot refused, read from the flash: a CRC-valid record that fails this firmware's
/// checks, not a missing or a good one; the calibration record only while no settings are
/// stored (the settings' calibration runs otherwise). And the build's calibration constant is
/// stored while the record does not hold it, so that the next image without it keeps it.
#[test]
fn the_boot_knows_what_it_refused_and_stores_the_builds_calibration_once() {
    use hter::persist::flash::{key, restore, restore_records};
    use hter::persist::{CalibrationRecord, Record};
    let mut store = open(MockFlash::<L4_PAGE>::blank(4), 4);
    let mut log = open_log(MockFlash::<L4_PAGE>::blank(4), 4);
    let constant = TwoPoint { gain: 1.013, offset_c: -0.42 };
    let r = block_on(restore_records(&mut store, Some(&gpc())));
    assert_eq!(r.refused(), 0, "nothing stored, nothing refused");
    assert_eq!(r.calibration_to_store(constant), Some(constant));
    // An older firmware's calibration (its bound was 10 °C of offset) and a model whose A has a
    // pole at 1.2; a good history.
    let old = CalibrationRecord { cal: TwoPoint { gain: 0.9, offset_c: 7.5 } }.encode();
    block_on(store.store(key::CALIBRATION, &old)).unwrap();
    block_on(store.save_model(&ModelRecord { theta: [-2.2, 1.2, -0.03, -0.03, 0.0, 0.0], k: 5 })).unwrap();
    block_on(store.save_history(&HistoryRecord::EMPTY)).unwrap();
    let mut store = reboot(store, 4);
    let r = block_on(restore_records(&mut store, Some(&gpc())));
    assert_eq!(r.refused(), Record::Calibration.bit() | Record::Model.bit());
    assert_eq!(r.boot(ResetCause::Other, Default::default()).refused, r.refused());
    assert_eq!(r.calibration_to_store(constant), Some(constant), "a refused record is no calibration");
    // Settings stored: their calibration runs, the record's refusal changes nothing.
    block_on(store.save_settings(&settings(1, 4.0, Law::Gpc))).unwrap();
    let r = block_on(restore(&mut store, &mut log, Some(gpc())));
    assert_eq!(r.refused(), Record::Model.bit());
    // The constant stored: found at the next boot, not stored again.
    block_on(store.save_calibration(constant)).unwrap();
    let mut store = reboot(store, 4);
    let r = block_on(restore_records(&mut store, Some(&gpc())));
    assert_eq!((r.calibration.value, r.calibration.status), (constant, LoadStatus::Restored));
    assert_eq!(r.refused(), Record::Model.bit());
    assert_eq!(r.calibration_to_store(constant), None);
    let other = TwoPoint { gain: 0.996, offset_c: 0.2 };
    assert_eq!(r.calibration_to_store(other), Some(other), "a new constant replaces it");
}

/// A region the storage layer finds corrupt (noise where its pages should be): `write_or_erase`
/// erases it and writes the record again, as the firmware's persist task does. The records
/// region comes back holding the record and says it was erased (the caller hands the rest over
/// again); the log comes back beginning with a plain `log_entries_lost` at the entry's time, then
/// the entry: `history` shows where the hole ends.
#[test]
fn a_corrupt_region_is_erased_and_written_again_and_the_log_says_where_its_hole_ends() {
    use hter::persist::flash::{write_or_erase, Erased};
    use hter::persist::Save as Rec;
    let (mut records, mut logs) = (0, 0);
    for seed in 1..=40u32 {
        // The records region corrupt, the log blank.
        let mut flash = MockFlash::<L4_PAGE>::blank(4);
        flash.bytes = noise(seed, 4 * L4_PAGE);
        let mut store = open(flash, 4);
        let mut log = open_log(MockFlash::<L4_PAGE>::blank(4), 4);
        let mut h = HistoryRecord::EMPTY;
        h.recorded_s = seed;
        let (result, erased) = block_on(write_or_erase(&mut store, &mut log, &Rec::History(h)));
        // Never a corruption left as it is (other errors, e.g. noise the flash will not program
        // over, are the flash's: the firmware's warning, no erase).
        assert_ne!(result, Err(StoreError::Corrupted), "seed {seed}");
        assert_ne!(erased, Erased::Log);
        if erased == Erased::Records {
            records += 1;
            assert_eq!(result, Ok(()), "seed {seed}");
            let mut store = reboot(store, 4);
            assert_eq!(block_on(store.load_history()).value, h, "seed {seed}");
        }

        // The log corrupt, the records region blank.
        let mut store = open(MockFlash::<L4_PAGE>::blank(4), 4);
        let mut flash = MockFlash::<L4_PAGE>::blank(4);
        flash.bytes = noise(seed, 4 * L4_PAGE);
        let mut log = open_log(flash, 4);
        // As stored (the interval's temperatures in 0.01 °C).
        let e = LogEntry::decode(&entry(seed).encode()).unwrap();
        let (result, erased) = block_on(write_or_erase(&mut store, &mut log, &Rec::Log(e)));
        assert_ne!(result, Err(StoreError::Corrupted), "seed {seed}");
        assert_ne!(erased, Erased::Records);
        if erased == Erased::Log {
            logs += 1;
            assert_eq!(result, Ok(()), "seed {seed}");
            assert_eq!(log_entries(&mut log), [LogEntry::Lost { t_s: e.t_s(), entries: 0 }, e], "seed {seed}");
        }
    }
    // Noise is corrupt to the storage layer in most seeds: both paths ran.
    assert!(records > 0 && logs > 0, "erased records {records}, logs {logs} of 40");
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

// ---- Fuzz: the boot from arbitrary flash (proptest; the `_long` twins in CI, ignored here) ----

/// What a boot restores from flash that it did not just write: a store region and a log region
/// as a board leaves them (every record kind written, pages turned), as the factory left them
/// (erased) or as noise, each with bytes and double words overwritten and words torn (failing
/// their ECC check) anywhere; and every record kind stored as arbitrary bytes (a valid record
/// with edits and its CRC written again, another version's length, noise). Whatever the flash
/// holds, [`hter::persist::flash::restore`] returns (no panic, no hang, repairs bounded, no ECC
/// damage left), each record it restores is valid by its type's rules and is what its decoder
/// makes of the stored bytes, each refused one is the default with the decoder's reason (the
/// boot log's), the app boots from it in range and with its freeze guard, and the regions take
/// records again (after the firmware's erase where the storage layer found them corrupt).
mod fuzz {
    use super::*;
    use hter::app::{App, AppConfig};
    use hter::calib::{MAX_CORRECTION_C, MIN_GAIN};
    use hter::failsafe::{StopInfo, StopKind, Stops};
    use hter::ident::commission::cabinet_plausible;
    use hter::persist::flash::{key, restore, Restored};
    use hter::persist::{crc32, CabinetRecord, CalibrationRecord};
    use hter::step::ValidConfig;
    use proptest::collection::vec;
    use proptest::prelude::*;
    use proptest::sample::select;
    use std::sync::OnceLock;

    const PAGES: usize = 4;
    const LAWS: &[Law] = &[Law::Gpc, Law::Pi, Law::OnOff];

    fn app_config() -> AppConfig {
        AppConfig {
            carrier: ValidConfig::DEFAULT,
            adaptive: gpc(),
            laws: LAWS,
            setpoint_c: 4.0,
            firmware: "hter fuzz",
            history_save_samples: 360,
            model_save_samples: 1440,
        }
    }

    /// A line a calibration gives ([`TwoPoint::from_points`]).
    fn plausible_line(cal: &TwoPoint) -> bool {
        let at_10 = (cal.gain - 1.0) * 10.0 + cal.offset_c;
        (MIN_GAIN..=1.1).contains(&cal.gain)
            && cal.offset_c.abs() <= MAX_CORRECTION_C
            && at_10.abs() <= MAX_CORRECTION_C
    }

    fn history(i: u32) -> HistoryRecord {
        let mut h = HistoryRecord::EMPTY;
        h.recorded_s = 3600 * i;
        h.note_reset(ResetCause::BrownOut);
        h.min_c = Some(1.5);
        h.max_c = Some(9.0);
        h
    }

    /// The two regions after a board's life: every record kind written over and over, log
    /// entries pushed until the log turned its pages.
    fn used() -> &'static (Vec<u8>, Vec<u8>) {
        static IMAGE: OnceLock<(Vec<u8>, Vec<u8>)> = OnceLock::new();
        IMAGE.get_or_init(|| {
            let mut store = open(MockFlash::<L4_PAGE>::blank(PAGES), PAGES);
            let mut log = open_log(MockFlash::<L4_PAGE>::blank(PAGES), PAGES);
            block_on(async {
                for i in 0..40 {
                    store.save_history(&history(i)).await.unwrap();
                    if i % 4 == 0 {
                        store.save_model(&ModelRecord::from_model(&START_MODEL_HTER1).unwrap()).await.unwrap();
                        store.save_settings(&settings(i, 4.5, Law::Pi)).await.unwrap();
                        store.save_calibration(TwoPoint { gain: 1.01, offset_c: -0.2 }).await.unwrap();
                        store
                            .save_cabinet(&CabinetRecord::from_model(&cabinet(-1.938_996, 0.271_719)).unwrap())
                            .await
                            .unwrap();
                    }
                }
                for i in 0..300 {
                    log.push(&entry(i)).await.unwrap();
                }
            });
            (store.release().bytes, log.release().bytes)
        })
    }

    /// What a region held before the damage.
    #[derive(Clone, Copy, Debug)]
    enum Image {
        Erased,
        Used,
        Noise(u32),
    }

    /// Damage to a region.
    #[derive(Clone, Copy, Debug)]
    enum Damage {
        /// A byte set.
        Byte(usize, u8),
        /// A double word set (all zeros, all ones, anything).
        Word(usize, u64),
        /// A double word failing its ECC check (a cut program or erase).
        Torn(usize),
        /// A page of noise.
        Page(usize, u32),
    }

    fn image() -> impl Strategy<Value = Image> {
        prop_oneof![1 => Just(Image::Erased), 6 => Just(Image::Used), 1 => any::<u32>().prop_map(Image::Noise)]
    }

    fn damage() -> impl Strategy<Value = Vec<Damage>> {
        let d = prop_oneof![
            (any::<usize>(), any::<u8>()).prop_map(|(at, x)| Damage::Byte(at, x)),
            (any::<usize>(), prop_oneof![Just(0u64), Just(u64::MAX), any::<u64>()])
                .prop_map(|(at, x)| Damage::Word(at, x)),
            any::<usize>().prop_map(Damage::Torn),
            (any::<usize>(), any::<u32>()).prop_map(|(p, seed)| Damage::Page(p, seed)),
        ];
        vec(d, 0..6)
    }

    /// A region of `image` with `damage`.
    fn region(image: Image, damage: &[Damage], used: &[u8], tear: Tear, nmi_only: bool) -> MockFlash<L4_PAGE> {
        let mut f = MockFlash::<L4_PAGE>::with_tear(PAGES, tear);
        f.nmi_only = nmi_only;
        match image {
            Image::Erased => {}
            Image::Used => f.bytes = used.to_vec(),
            Image::Noise(seed) => f.bytes = noise(seed | 1, PAGES * L4_PAGE),
        }
        let words = f.torn.len();
        for d in damage {
            match *d {
                Damage::Byte(at, x) => f.bytes[at % (PAGES * L4_PAGE)] = x,
                Damage::Word(at, x) => {
                    let w = at % words;
                    f.bytes[w * 8..w * 8 + 8].copy_from_slice(&x.to_le_bytes());
                }
                Damage::Torn(at) => f.torn[at % words] = true,
                Damage::Page(p, seed) => {
                    let p = p % PAGES;
                    f.bytes[p * L4_PAGE..(p + 1) * L4_PAGE].copy_from_slice(&noise(seed | 1, L4_PAGE));
                }
            }
        }
        f
    }

    /// A boot's reset and the stops it found in RAM.
    fn start() -> impl Strategy<Value = (ResetCause, Stops, bool)> {
        let stop = proptest::option::of(
            (select(StopKind::ALL.to_vec()), any::<u32>()).prop_map(|(k, d)| StopInfo::new(k, 0, 0, d)),
        );
        (
            select(vec![ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other]),
            (stop.clone(), stop, any::<bool>()).prop_map(|(earlier, latest, fresh)| Stops { earlier, latest, fresh }),
            any::<bool>(),
        )
    }

    /// Every restored record valid by its type's rules; every refused one the default.
    fn restored_valid(r: &Restored) -> Result<(), TestCaseError> {
        if let Ok(s) = r.settings {
            let (lo, hi) = hter::iface::SETPOINT_RANGE_C;
            prop_assert!((lo..=hi).contains(&s.setpoint_c), "{s:?}");
            prop_assert!(s.calibration().is_ok_and(|c| plausible_line(&c)), "{s:?}");
            prop_assert_eq!(SettingsRecord::decode(&s.encode()), Ok(s));
        }
        prop_assert!(plausible_line(&r.calibration.value), "{:?}", r.calibration);
        if r.calibration.status != LoadStatus::Restored {
            prop_assert_eq!(r.calibration.value, TwoPoint::IDENTITY);
        }
        let h = r.history.value;
        prop_assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
        if r.history.status != LoadStatus::Restored {
            prop_assert_eq!(h, HistoryRecord::EMPTY);
        }
        let a = r.adaptive.expect("restored with a self-tuner");
        if a.status == LoadStatus::Restored {
            let tuner = SelfTuning::new(a.value, 10.0, 0.45);
            prop_assert!(tuner.is_ok(), "{:?}", tuner.err());
        } else {
            prop_assert_eq!(a.value, gpc());
        }
        if let Ok(m) = r.cabinet {
            prop_assert!(cabinet_plausible(&gpc(), &m).is_ok(), "{m:?}");
        }
        Ok(())
    }

    /// The app booted from `r` starts in range, with the build's guards, and controls.
    fn app_boots(r: &Restored, (reset, stops, button): (ResetCause, Stops, bool)) -> Result<(), TestCaseError> {
        let mut boot = r.boot(reset, stops);
        boot.button_held = button;
        let mut app = App::new(app_config(), &boot);
        let s = *app.settings();
        let (lo, hi) = hter::iface::SETPOINT_RANGE_C;
        prop_assert!((lo..=hi).contains(&s.setpoint_c) && LAWS.contains(&s.law), "{s:?}");
        if r.settings.is_err() {
            prop_assert_eq!((s.setpoint_c, s.law), (4.0, Law::Gpc), "the defaults");
        }
        prop_assert!(plausible_line(&app.carrier().config().cal));
        prop_assert_eq!(app.carrier().config().supervisor, ValidConfig::DEFAULT.get().supervisor);
        for k in 0..20u64 {
            let out = app.sample_celsius(k * 10_000, 4.0 + (k % 2) as f32 * 0.01);
            prop_assert!((0.0..=1.0).contains(&out.step.duty.get()), "{out:?}");
        }
        while let Some(save) = app.next_save() {
            if let hter::persist::Save::History(h) | hter::persist::Save::AlarmHistory(h) = save {
                prop_assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
            }
        }
        Ok(())
    }

    fn check_flash(
        (store_image, store_damage): (Image, Vec<Damage>),
        (log_image, log_damage): (Image, Vec<Damage>),
        (tear, nmi_only): (Tear, bool),
        start: (ResetCause, Stops, bool),
    ) -> Result<(), TestCaseError> {
        let (s, l) = used();
        let mut store = open(region(store_image, &store_damage, s, tear, nmi_only), PAGES);
        let mut log = open_log(region(log_image, &log_damage, l, tear, nmi_only), PAGES);
        let r = block_on(restore(&mut store, &mut log, Some(gpc())));
        let bound = 2 * PAGES + 6 * MAX_REPAIRS;
        prop_assert!(usize::from(r.repairs.total()) <= bound, "{:?}", r.repairs);
        restored_valid(&r)?;
        // Every entry the log hands out reads as it would be written.
        let mut entries = Vec::new();
        let walked = block_on(log.for_each(0, async |e: &LogEntry| {
            entries.push(*e);
            true
        }));
        for e in &entries {
            let again = LogEntry::decode(&e.encode()).map(|x| x.encode());
            prop_assert_eq!(again, Ok(e.encode()), "{:?}", e);
        }
        // The record's time goes on from the newest entry the boot found: none the log hands
        // out later is newer. (Not the same entries: over pages of noise, which no power cut
        // on the L4 leaves, the storage layer's walk erases a page it finds nothing in, and the
        // next walk may start elsewhere.)
        if let (Ok(last), Ok(_)) = (r.log_last_s, walked) {
            prop_assert!(entries.iter().all(|e| e.t_s() <= last), "{last} s, {entries:?}");
        }
        app_boots(&r, start)?;
        // The regions take records again, after an erase where the storage layer refuses
        // (what the firmware's persist task does).
        let h = history(7);
        block_on(async {
            if store.save_history(&h).await.is_err() {
                store.erase_all().await.unwrap();
                store.save_history(&h).await.unwrap();
            }
            assert_eq!(
                store.load_history().await,
                hter::persist::flash::Loaded { value: h, status: LoadStatus::Restored }
            );
            if log.push(&entry(1)).await.is_err() {
                log.erase_all().await.unwrap();
                log.push(&entry(1)).await.unwrap();
            }
        });
        let (store_flash, log_flash) = (store.release(), log.release());
        prop_assert_eq!((store_flash.torn_words(), log_flash.torn_words()), (0, 0), "ECC damage left");
        Ok(())
    }

    // -- Arbitrary records stored whole (the storage layer's CRC right), through the boot.

    /// Writes the CRC of a frame's bytes before its last four into them.
    fn reframe(b: &mut [u8]) {
        let n = b.len() - 4;
        let crc = crc32(&b[..n]);
        b[n..].copy_from_slice(&crc.to_le_bytes());
    }

    /// A record's bytes: one of `frames` edited (the CRC written again) or as it is, or noise.
    fn record(frames: Vec<Vec<u8>>, len: usize) -> impl Strategy<Value = Option<Vec<u8>>> {
        let edit = (any::<usize>(), prop_oneof![any::<u32>(), any::<f32>().prop_map(f32::to_bits)], 1usize..=4);
        prop_oneof![
            1 => Just(None),
            4 => (select(frames), vec(edit, 0..4)).prop_map(|(mut b, edits)| {
                let body = b.len() - 4;
                for (at, word, n) in edits {
                    let at = at % body;
                    for (d, s) in b[at..body].iter_mut().zip(&word.to_le_bytes()[..n]) {
                        *d = *s;
                    }
                }
                reframe(&mut b);
                Some(b)
            }),
            1 => vec(any::<u8>(), 0..=2 * len).prop_map(Some),
        ]
    }

    fn records() -> impl Strategy<Value = [Option<Vec<u8>>; 5]> {
        let older = |v: u8, n: usize| {
            let mut b = history(3).encode()[..n].to_vec();
            b[1] = v;
            reframe(&mut b);
            b
        };
        (
            record(vec![settings(5, 4.5, Law::Pi).encode().to_vec()], SettingsRecord::LEN),
            record(vec![CalibrationRecord { cal: TwoPoint { gain: 1.01, offset_c: -0.2 } }.encode().to_vec()], 14),
            record(vec![ModelRecord::from_model(&START_MODEL_HTER2).unwrap().encode().to_vec()], ModelRecord::LEN),
            record(
                vec![CabinetRecord::from_model(&cabinet(-1.938_996, 0.271_719)).unwrap().encode().to_vec()],
                CabinetRecord::LEN,
            ),
            record(
                vec![
                    history(3).encode().to_vec(),
                    older(5, HistoryRecord::LEN_V5),
                    older(4, HistoryRecord::LEN_V4),
                    older(3, HistoryRecord::LEN_V3),
                    older(2, HistoryRecord::LEN_V2),
                ],
                HistoryRecord::LEN,
            ),
        )
            .prop_map(|(a, b, c, d, e)| [a, b, c, d, e])
    }

    /// What the boot must make of `bytes` under a key: the decoder's value, or its reason.
    fn expect<T: PartialEq + std::fmt::Debug>(
        got: Result<T, LoadStatus>,
        bytes: &Option<Vec<u8>>,
        decode: impl Fn(&[u8]) -> Result<T, DecodeError>,
    ) -> Result<(), TestCaseError> {
        let want = match bytes {
            None => Err(LoadStatus::Missing),
            Some(b) if b.len() > HistoryRecord::LEN => Err(LoadStatus::Invalid(DecodeError::Length)),
            Some(b) => decode(b).map_err(LoadStatus::Invalid),
        };
        prop_assert_eq!(got, want);
        Ok(())
    }

    fn loaded<T>(l: hter::persist::flash::Loaded<T>) -> Result<T, LoadStatus> {
        match l.status {
            LoadStatus::Restored => Ok(l.value),
            e => Err(e),
        }
    }

    fn check_records(recs: &[Option<Vec<u8>>; 5], start: (ResetCause, Stops, bool)) -> Result<(), TestCaseError> {
        let mut store = open(MockFlash::<L4_PAGE>::blank(PAGES), PAGES);
        let mut log = open_log(MockFlash::<L4_PAGE>::blank(PAGES), PAGES);
        let keys = [key::SETTINGS, key::CALIBRATION, key::MODEL, key::CABINET, key::HISTORY];
        let mut stored = recs.clone();
        for (k, b) in keys.iter().zip(stored.iter_mut()) {
            if let Some(bytes) = b {
                // An item the storage layer's buffer cannot hold is not stored (nor read).
                if block_on(store.store(*k, bytes)).is_err() {
                    *b = None;
                }
            }
        }
        let mut store = reboot(store, PAGES);
        let r = block_on(restore(&mut store, &mut log, Some(gpc())));
        restored_valid(&r)?;
        let [settings, cal, model, cab, hist] = &stored;
        expect(r.settings, settings, SettingsRecord::decode)?;
        expect(loaded(r.calibration), cal, |b| CalibrationRecord::decode(b).map(|r| r.cal))?;
        expect(loaded(r.history), hist, HistoryRecord::decode)?;
        let a = r.adaptive.expect("restored with a self-tuner");
        expect(loaded(a), model, |b| ModelRecord::decode(b).and_then(|r| r.restore(&gpc())))?;
        expect(r.cabinet, cab, |b| CabinetRecord::decode(b, &gpc()))?;
        app_boots(&r, start)
    }

    fn tear() -> impl Strategy<Value = (Tear, bool)> {
        (select(vec![Tear::Ecc, Tear::Readable]), any::<bool>())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        #[test]
        fn arbitrary_flash_restores_valid_records_or_defaults(
            s in (image(), damage()), l in (image(), damage()), t in tear(), start in start()
        ) {
            check_flash(s, l, t, start)?;
        }

        #[test]
        fn arbitrary_stored_records_restore_as_their_decoders_read_them(recs in records(), start in start()) {
            check_records(&recs, start)?;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 50_000, ..ProptestConfig::default() })]
        #[test]
        #[ignore = "many cases: CI runs it in release with `-- --ignored`"]
        fn arbitrary_flash_restores_valid_records_or_defaults_long(
            s in (image(), damage()), l in (image(), damage()), t in tear(), start in start()
        ) {
            check_flash(s, l, t, start)?;
        }

        #[test]
        #[ignore = "many cases: CI runs it in release with `-- --ignored`"]
        fn arbitrary_stored_records_restore_as_their_decoders_read_them_long(recs in records(), start in start()) {
            check_records(&recs, start)?;
        }
    }
}
